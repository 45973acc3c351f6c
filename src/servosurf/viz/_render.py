"""Off-screen 3-D renders of height maps (pyvista), with a matplotlib fallback.

pyvista is imported inside :func:`render_surface`, never at package import. The
render runs off-screen (VTK 9.4+ wheels pick an EGL or OSMesa context when there is
no display). Whether that works is checked once per process in a child process,
because VTK can abort the whole process, rather than raise, when no OpenGL
context can be created. If it does not work, or the render raises, the PNG is
drawn by matplotlib's 3-D axes instead, with the reason in its title and a
:class:`RenderFallbackWarning`.

Display units appear only here: lateral positions in um, heights in nm (colour
bar) and um times the exaggeration (z axis). Inputs are SI (m).
"""

from __future__ import annotations

import contextlib
import functools
import math
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import ConfigError
from ..metrology._surface import Surface
from ._mesh import _check_exaggeration, _triangulate

__all__ = ["render_surface", "RenderFallbackWarning", "MAX_RENDER_POINTS"]

#: Maps with more pixels are subsampled (every k-th row and column) for pyvista.
MAX_RENDER_POINTS: int = 1_000_000

#: The matplotlib fallback draws at most this many points (it is much slower).
MAX_FALLBACK_POINTS: int = 40_000

#: Automatic z exaggeration: the height range is drawn as this fraction of the
#: larger lateral extent (then rounded down to 1, 2 or 5 times a power of ten).
AUTO_RELIEF: float = 0.25

#: Seconds allowed for the child process that checks off-screen rendering.
_PROBE_TIMEOUT: float = 120.0

_BACKENDS = ("auto", "pyvista", "matplotlib")

_PROBE_CODE = """
import contextlib
import pyvista as pv
quiet = getattr(pv, "vtk_verbosity", None)  # pyvista >= 0.45
with quiet("off") if quiet else contextlib.nullcontext():
    pl = pv.Plotter(off_screen=True, window_size=(64, 64))
    pl.add_mesh(pv.Sphere(), color="white")
    img = pl.screenshot(return_img=True)
    pl.close()
print("ok" if img.std() > 0 else "blank")
"""


class RenderFallbackWarning(RuntimeWarning):
    """pyvista could not render off-screen; matplotlib drew the PNG instead."""


@functools.cache
def _offscreen_problem() -> str | None:
    """Return why pyvista cannot render off-screen here, or None if it can.

    Runs a 64 x 64 render in a child process once per process (about 1-2 s).
    """
    try:
        res = subprocess.run(
            [sys.executable, "-c", _PROBE_CODE],
            capture_output=True,
            text=True,
            timeout=_PROBE_TIMEOUT,
            check=False,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        return f"off-screen render check failed ({type(exc).__name__})"
    if res.returncode != 0:
        last = (res.stderr.strip().splitlines() or [""])[-1][:120]
        return f"no off-screen OpenGL context (exit status {res.returncode}) {last}"
    if res.stdout.strip().splitlines()[-1:] != ["ok"]:
        return "off-screen render came out blank"
    return None


def _atomic_png(path: Path):
    """Temporary ``.png`` path next to ``path``, moved into place on success."""
    from .._atomic import atomic_path

    return atomic_path(path, suffix=".png")


def _stride(shape: tuple[int, int], max_points: int) -> int:
    """Smallest row/column stride leaving at most ``max_points`` grid points."""
    ny, nx = shape
    k = max(1, math.ceil(math.sqrt(ny * nx / max_points)))
    while math.ceil(ny / k) * math.ceil(nx / k) > max_points:
        k += 1
    return k


def _nice_floor(v: float) -> float:
    """Largest 1, 2 or 5 times a power of ten not above ``v`` (``v > 0``)."""
    e = math.floor(math.log10(v))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**e <= v * (1 + 1e-12):
            return m * 10.0**e
    return 10.0**e  # pragma: no cover


def _scene(
    surface: Surface, stride: int, z_exaggeration: float | None
) -> dict[str, Any]:
    """Display-unit geometry: points in um (or px), heights in nm, labels."""
    xyz, faces, _ = _triangulate(surface, stride)
    lateral = 1e6 if surface.calibrated else 1.0
    unit = "um" if surface.calibrated else "px"
    h = xyz[:, 2] - xyz[:, 2].mean()  # m, about the mean of the drawn points
    extent = max(np.ptp(xyz[:, 0]), np.ptp(xyz[:, 1])) * lateral
    ptp_um = float(np.ptp(h)) * 1e6
    if z_exaggeration is None:
        exag = _nice_floor(AUTO_RELIEF * extent / ptp_um) if ptp_um > 0 else 1.0
    else:
        exag = z_exaggeration
    # lateral axes about the map centre: short tick labels (a field 10 mm off the
    # spindle axis would otherwise read 1.006e+04 um)
    centre = [0.5 * (xyz[:, i].min() + xyz[:, i].max()) for i in (0, 1)]
    if not surface.calibrated or max(abs(c) for c in centre) < 10 * extent / lateral:
        centre = [0.0, 0.0]
    points = np.column_stack([(xyz[:, 0] - centre[0]) * lateral,
                              (xyz[:, 1] - centre[1]) * lateral, h * 1e6 * exag])
    ztitle = f"z (um, drawn x{exag:g})" if exag != 1 else "z (um)"
    xtitle, ytitle = (f"{a} - {c * 1e3:.4g} mm ({unit})" if c else f"{a} ({unit})"
                      for a, c in zip("xy", centre, strict=True))
    # axis label ranges in true units (the drawn z is exaggerated)
    ranges = [
        float(points[:, 0].min()),
        float(points[:, 0].max()),
        float(points[:, 1].min()),
        float(points[:, 1].max()),
        float(h.min()) * 1e6,
        float(h.max()) * 1e6,
    ]
    return {
        "points": points,
        "faces": faces,
        "height_nm": h * 1e9,
        "exaggeration": exag,
        "xtitle": xtitle,
        "ytitle": ytitle,
        "ztitle": ztitle,
        "bar_title": "z - mean (nm)",
        "axes_ranges": ranges,
    }


def _add_rulers(pl: Any, scene: dict[str, Any]) -> None:
    """Scale rulers along two front edges and one vertical edge of the mesh.

    Three separate rulers instead of a bounding box's axes: the box puts the end
    labels of all three axes on its shared corners, where they overlap. Each ruler
    reads from 0 at its start, in um (the z ruler in true um: the drawn height is
    divided by the exaggeration).
    """
    p = scene["points"]
    (x0, y0, z0), (x1, y1, z1) = p.min(axis=0), p.max(axis=0)
    gap = 0.1 * max(x1 - x0, y1 - y0)
    unit = scene["xtitle"].rsplit("(", 1)[-1].rstrip(")")
    common = {"font_size_factor": 0.55, "label_color": "black",
              "tick_color": "black", "number_minor_ticks": 1}
    # isometric view from (+x, +y, +z): the edges at y = y1 and x = x1 face it
    pl.add_ruler([x0, y1 + gap, z0], [x1, y1 + gap, z0], title=f"x ({unit})",
                 number_labels=3, label_format="%.0f", **common)
    pl.add_ruler([x1 + gap, y0, z0], [x1 + gap, y1, z0], title=f"y ({unit})",
                 number_labels=3, label_format="%.0f", **common)
    if z1 > z0:  # at the left corner, away from the colour bar
        nm = (z1 - z0) / scene["exaggeration"] < 0.1  # drawn in um
        pl.add_ruler([x1 + gap, y0 - gap, z0], [x1 + gap, y0 - gap, z1],
                     title="", number_labels=2,
                     label_format="z %.3g nm" if nm else "z %.3g um",
                     scale=(1e3 if nm else 1.0) / scene["exaggeration"], **common)


def _render_pyvista(
    scene: dict[str, Any],
    tmp: Path,
    title: str | None,
    cmap: str,
    window_size: tuple[int, int],
) -> None:
    import pyvista as pv

    faces = np.column_stack(
        [np.full(len(scene["faces"]), 3, dtype=np.int64), scene["faces"]]
    ).ravel()
    mesh = pv.PolyData(scene["points"], faces)
    mesh.point_data["height_nm"] = scene["height_nm"]
    # "error": keep VTK's stderr quiet about the display it tries before EGL
    quiet = getattr(pv, "vtk_verbosity", None)  # pyvista >= 0.45
    with quiet("error") if quiet else contextlib.nullcontext():
        pl = pv.Plotter(off_screen=True, window_size=list(window_size))
        try:
            pl.set_background("white")
            pl.add_mesh(
                mesh,
                scalars="height_nm",
                cmap=cmap,
                smooth_shading=True,
                scalar_bar_args={
                    "title": scene["bar_title"],
                    "vertical": True,
                    "color": "black",
                    "fmt": "%.4g",
                    "position_x": 0.84,
                    "position_y": 0.12,
                    "width": 0.06,
                    "height": 0.7,
                    "n_labels": 5,
                },
            )
            _add_rulers(pl, scene)
            exag = scene["exaggeration"]
            text = "\n".join(t for t in (
                title, f"heights drawn x{exag:g}" if exag != 1 else "") if t)
            if text:
                pl.add_text(text, position="upper_edge", font_size=12, color="black")
            pl.view_isometric()
            pl.camera.zoom(0.9)  # leave room for the colour bar
            pl.screenshot(str(tmp))
        finally:
            pl.close()
            pl.deep_clean()
            del pl


def _render_matplotlib(
    scene: dict[str, Any],
    tmp: Path,
    title: str,
    cmap: str,
    window_size: tuple[int, int],
) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    dpi = 100
    fig = Figure(figsize=(window_size[0] / dpi, window_size[1] / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    p = scene["points"]
    z_true = p[:, 2] / scene["exaggeration"]  # tick labels in true um
    ax.plot_trisurf(
        p[:, 0],
        p[:, 1],
        z_true,
        triangles=scene["faces"],
        cmap=cmap,
        linewidth=0.0,
        antialiased=False,
    )
    h = scene["height_nm"]
    sm = ScalarMappable(norm=Normalize(float(h.min()), float(h.max())), cmap=cmap)
    fig.colorbar(sm, ax=ax, shrink=0.6, pad=0.12, label=scene["bar_title"])
    ax.set_xlabel(scene["xtitle"])
    ax.set_ylabel(scene["ytitle"])
    ax.set_zlabel(scene["ztitle"])
    # the exaggeration goes into the box aspect, not into the data
    spans = [max(float(np.ptp(p[:, i])), 1e-12) for i in range(3)]
    ax.set_box_aspect(spans)
    ax.set_title(title, fontsize=9)
    fig.savefig(tmp, format="png", dpi=dpi)


def render_surface(
    surface: Surface,
    path: str | Path,
    *,
    z_exaggeration: float | None = None,
    title: str | None = None,
    cmap: str = "viridis",
    window_size: tuple[int, int] = (1200, 900),
    backend: Literal["auto", "pyvista", "matplotlib"] = "auto",
) -> Path:
    """Render a height map in 3-D off-screen and write it as a PNG.

    Parameters
    ----------
    surface : Surface
        Height map in m; rows are y, columns are x. NaN pixels are left out
        (quads with a NaN corner are not drawn).
    path : str or Path
        Output PNG; missing parent folders are created. Written atomically.
    z_exaggeration : float or None, default: None
        Factor on the heights (dimensionless). ``None`` picks one that draws the
        height range as about :data:`AUTO_RELIEF` of the larger lateral extent,
        rounded down to 1, 2 or 5 times a power of ten; the z axis title states it.
    title : str or None, default: None
        Text drawn at the top of the image.
    cmap : str, default: "viridis"
        A matplotlib colormap name.
    window_size : tuple of int, default: (1200, 900)
        Image width and height in pixels.
    backend : {"auto", "pyvista", "matplotlib"}, default: "auto"
        ``"auto"`` renders with pyvista when off-screen rendering works here and
        falls back to matplotlib otherwise (with a warning). ``"pyvista"`` skips
        the check (in a process without any OpenGL context VTK may abort);
        ``"matplotlib"`` draws with matplotlib's 3-D axes.

    Returns
    -------
    Path
        The written PNG.

    Raises
    ------
    ImportError
        If pyvista is not installed (``backend`` "auto" or "pyvista").
    ConfigError
        If ``surface`` is not a Surface with a 2 x 2 block of valid pixels, or
        an option is invalid.

    Warns
    -----
    RenderFallbackWarning
        With ``backend="auto"``, when pyvista cannot render off-screen and
        matplotlib drew the PNG; the image title states why.

    Notes
    -----
    The map becomes a triangle mesh (see :func:`~servosurf.viz.surface_to_mesh`)
    in display units: x and y in um (pixels if uncalibrated), z in um times the
    exaggeration, coloured by the height about the mean in nm. Maps larger than
    :data:`MAX_RENDER_POINTS` pixels (:data:`MAX_FALLBACK_POINTS` for the
    matplotlib fallback) are subsampled every k-th row and column.
    """
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    if backend not in _BACKENDS:
        raise ConfigError(f"backend must be one of {_BACKENDS}, got {backend!r}")
    if z_exaggeration is not None:
        z_exaggeration = _check_exaggeration(z_exaggeration)
    if title is not None and not isinstance(title, str):
        raise ConfigError(f"title must be a str or None, got {type(title).__name__}")
    try:
        w, h = (int(v) for v in window_size)
    except (TypeError, ValueError):
        raise ConfigError(
            f"window_size must be (width, height) in pixels, got {window_size!r}"
        ) from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise ConfigError(
            f"window_size must be within 16..8192 pixels, got {window_size!r}"
        )
    import matplotlib

    if not isinstance(cmap, str) or cmap not in matplotlib.colormaps:
        raise ConfigError(f"cmap must be a matplotlib colormap name, got {cmap!r}")
    path = Path(path)

    reason = None
    if backend != "matplotlib":
        try:
            import pyvista  # noqa: F401
        except ImportError:
            raise ImportError(
                "3D rendering needs pyvista: pip install pyvista"
            ) from None
        scene = _scene(
            surface, _stride(surface.shape, MAX_RENDER_POINTS), z_exaggeration
        )
        if backend == "auto":
            reason = _offscreen_problem()
        if reason is None:
            try:
                with _atomic_png(path) as tmp:
                    _render_pyvista(scene, tmp, title, cmap, (w, h))
                return path
            except Exception as exc:
                if backend == "pyvista":
                    raise
                reason = f"pyvista render failed: {type(exc).__name__}: {exc}"[:160]
        warnings.warn(
            f"3-D render drawn with matplotlib instead of pyvista: {reason}",
            RenderFallbackWarning,
            stacklevel=2,
        )

    scene = _scene(surface, _stride(surface.shape, MAX_FALLBACK_POINTS), z_exaggeration)
    text = title or ""
    if reason is not None:
        text = f"{text}\n(matplotlib fallback: {reason})".lstrip("\n")
    with _atomic_png(path) as tmp:
        _render_matplotlib(scene, tmp, text, cmap, (w, h))
    return path
