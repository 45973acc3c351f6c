"""A whole face from a facing toolpath and a run configuration, end to end.

:func:`face_toolpath` stretches a facing toolpath over a face of a given radius;
:func:`simulate_face_run` realises the vibration record of the run's loop (a
memory-mapped ``vibration.npy``), tiles the face into a Zarr array
(:func:`~servosurf.scale.simulate_face`) and reads back an area-averaged preview
with the face's statistics. The ``face`` command parses its flags, calls these and
writes the summary.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import stage
from ..errors import ConfigError
from ..run import RunConfig, load_run
from ._face import FaceResult, face_field, face_preview, simulate_face
from ._vibration import MemmapDeviation, write_vibration

__all__ = ["face_toolpath", "simulate_face_run", "FaceRun"]


def face_toolpath(toolpath, radius: float, pitch: float):
    """The facing toolpath over a whole face of ``radius`` m at ``pitch`` m.

    The path runs from one arc half-width outside the face (the tool's reach) to
    the axis with the file's feed, speed and depth; the field is
    :func:`~servosurf.scale.face_field`.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        A facing toolpath (TOML file or built-in name).
    radius : float
        Face radius, in m.
    pitch : float
        Grid pitch, in m.

    Returns
    -------
    ToolpathSpec
        The toolpath with its field and path over the face.

    Raises
    ------
    ConfigError
        When the toolpath is not a facing cut.
    """
    from ..toolpath import ToolpathSpec, load_toolpath

    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    if spec.kind != "facing":
        raise ConfigError(
            f"{toolpath}: face needs a facing toolpath, got {spec.kind!r}"
        )
    fld = face_field(radius, pitch)
    reach = spec.tool.chord_half_width(spec.path.depth_of_cut + 1e-6)
    path = dataclasses.replace(spec.path, r_start=radius + reach, r_end=0.0)
    return dataclasses.replace(spec, field=fld, path=path)


@dataclass(frozen=True, eq=False)
class FaceRun:
    """A whole face: the tiled array, its vibration record and its preview.

    Attributes
    ----------
    face : FaceResult
        The Zarr array and the run's throughput.
    radius : float
        Face radius, in m.
    pitch : float
        Grid pitch, in m.
    preview : Surface
        Area-averaged preview, heights about the face mean in m.
    step : int
        Preview block side, in pixels.
    stats : dict
        ``mean_m``, ``sq_m``, ``min_m``, ``max_m``, ``valid_points`` of every
        valid pixel (m).
    summary : dict
        JSON-ready values (SI units): the loop's set-up and the vibration record
        (with vibration), the throughput and the face's statistics.
    """

    face: FaceResult
    radius: float
    pitch: float
    preview: Any
    step: int
    stats: dict[str, float]
    summary: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready summary (a copy)."""
        return dict(self.summary)

    def plot(self, folder: str | Path) -> Path:
        """Write the preview map ``face.png`` into ``folder``.

        Parameters
        ----------
        folder : str or Path
            Output folder (existing).

        Returns
        -------
        Path
            The PNG file.
        """
        from ..viz import plot_map

        step = self.step
        what = f"{step} x {step}-pixel block means" if step > 1 else "every pixel"
        return plot_map(
            self.preview, Path(folder) / "face.png", robust=0.5, dpi=150,
            title=f"{2 * self.radius * 1e3:g} mm face at {self.pitch * 1e6:g} um "
            f"pitch ({what}),\nheight about the face mean "
            f"({self.stats['mean_m'] * 1e9:.4g} nm)")


def simulate_face_run(spec, folder: str | Path, run: RunConfig | str | None = None,
                      *, radius: float, chunk: int = 1024, vibration: bool = True,
                      client=None, preview_window: int | None = None,
                      progress: Callable[[Iterable], Iterable] | None = None
                      ) -> FaceRun:
    """Simulate a whole face: vibration record, tiled Zarr array and preview.

    Parameters
    ----------
    spec : ToolpathSpec
        The facing toolpath over the face (:func:`face_toolpath`).
    folder : str or Path
        Existing folder for ``vibration.npy`` and ``face.zarr``.
    run : RunConfig or str, optional
        Machine, bandwidth (Hz), mass (kg) and seed of the vibration realisation
        (default: every default of :class:`~servosurf.run.RunConfig`).
    radius : float
        Face radius, in m.
    chunk : int, default: 1024
        Tile side, in pixels.
    vibration : bool, default: True
        Add the seeded vibration realisation (False: kinematic surface).
    client : distributed.Client, optional
        Run the tiles on this dask cluster.
    preview_window : int, optional
        Read window of the preview, in pixels (default ``max(chunk, 256)``).
    progress : callable, optional
        Wraps the iterable of vibration blocks (a progress bar).

    Returns
    -------
    FaceRun
        The array, the preview and the summary.

    Raises
    ------
    ConfigError
        When the loop is unstable at the run's bandwidth.
    """
    from ..metrology import Surface
    from ..servo import ServoLoop

    cfg = load_run(run)
    out = Path(folder)
    fld = spec.field
    summary: dict[str, Any] = {}
    deviation = None
    if vibration:
        machine = cfg.machine_model()
        loop = ServoLoop(machine)
        if not loop.is_stable():
            raise ConfigError(f"the loop is unstable at "
                              f"{machine.controller.bandwidth:g} Hz; lower --bandwidth")
        n = int(np.ceil(spec.path.duration * loop.fs)) + 4
        vib = out / "vibration.npy"
        with stage(
            f"vibration realisation: {n} samples ({n / loop.fs:.0f} s of cutting)"
        ):
            write_vibration(loop, vib, n, seed=cfg.seed, progress=progress)
        deviation = MemmapDeviation(str(vib.resolve()))
        summary.update(bandwidth_hz=cfg.bandwidth, moving_mass_kg=cfg.mass,
                       vibration_record={
                           "file": str(vib), "unit": "m", "dtype": "float32",
                           "sample_rate_hz": loop.fs, "t0_s": 0.0,
                           "what": "tool-height deviation, sample k at t = k / "
                                   "sample_rate_hz from the start of the cut"})
    store = out / "face.zarr"
    with stage(f"face {fld.ny} x {fld.nx} px in {chunk}-px tiles"):
        res = simulate_face(spec, str(store), field=fld, face_radius=radius,
                            chunk=(chunk, chunk), deviation=deviation, client=client,
                            n_threads=cfg.n_threads)
    summary.update(seconds=res.seconds, points=res.n_points,
                   points_per_s=res.points_per_s, tasks=res.n_tasks,
                   path_samples=res.n_samples, zarr=str(store),
                   zarr_attributes=dict(res.array.attrs))
    with stage("area-averaged preview and statistics"):
        # about as many preview pixels as the PNG shows (dpi 150): no resampling
        window = max(chunk, 256) if preview_window is None else preview_window
        z, step, stats = face_preview(res.array, max_pixels=560, window=window)
        half = 0.5 * (step - 1)
        prev = Surface(z - stats["mean_m"], fld.pitch_x * step, fld.pitch_y * step,
                       x0=fld.x0 + half * fld.pitch_x, y0=fld.y0 + half * fld.pitch_y)
    summary.update(preview_step=step, preview_block_px=step,
                   face_mean_m=stats["mean_m"], face_sq_m=stats["sq_m"],
                   face_pv_m=stats["max_m"] - stats["min_m"],
                   face_statistics="every valid pixel, about the mean, "
                   "unfiltered (no levelling: the face is flat by construction)")
    pitch = float(fld.pitch_x)
    return FaceRun(face=res, radius=float(radius), pitch=pitch, preview=prev,
                   step=step, stats=stats, summary=summary)
