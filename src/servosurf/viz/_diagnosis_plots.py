"""Pictures of a diagnosis: before/after residuals, spectra, FRFs, maps, profiles.

Draws the data :func:`servosurf.diagnose.figure_data` gathers (SI units): every
picture shows the recording against the nominal model ("before") and the fitted
model ("after") and marks the located mismatch (bands, lines, time windows).
Display units (nm, ms, mN, degree) are used here only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import figure, save

__all__ = ["diagnosis_figures"]

#: Picture kinds of :func:`diagnosis_figures`.
KINDS = ("spectrum", "residual", "frf", "map", "profile")


def _marks(ax, marks, *, scale: float = 1.0, time: bool = False) -> None:
    """Shade time windows (``time``) or frequency bands and lines on ``ax``."""
    for d in marks:
        if time and "t_s" in d:
            ax.axvspan(d["t_s"][0] * scale, d["t_s"][1] * scale, color="C3", alpha=0.15)
        elif not time and "band_hz" in d:
            ax.axvspan(
                d["band_hz"][0] * scale, d["band_hz"][1] * scale, color="C3", alpha=0.12
            )
        elif not time and "frequency_hz" in d:
            ax.axvline(d["frequency_hz"] * scale, color="C3", lw=0.8, ls=":")


def _spectrum(g: dict, path: Path) -> Path:
    fig, ax = figure(figsize=(8, 4.5))
    f = g["frequency_hz"]
    ax.loglog(
        f, g["measured_m2_per_hz"], color="0.75", lw=0.6, label="measured (averaged)"
    )
    ax.loglog(f, g["before_m2_per_hz"], "C0--", lw=1.2, label="model before")
    ax.loglog(f, g["after_m2_per_hz"], "C3-", lw=1.2, label="after")
    _marks(ax, g.get("marks", ()))
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("following-error PSD [m^2/Hz]")
    ax.set_title(
        f"{g['recording']}: idle following-error spectrum ({g['records']} records)"
    )
    ax.legend(fontsize=8)
    return save(fig, path)


def _residual(g: dict, path: Path) -> Path:
    force = "force_residual_before_n" in g
    rows = 3 if force else 2
    fig, ax = figure(rows, 1, figsize=(9, 2.6 * rows))
    t = g["time_s"] * 1e3
    for lab, c in (("before", "C0"), ("after", "C3")):
        ax[0].plot(
            t, g[f"residual_{lab}_m"] * 1e9, color=c, lw=0.5, label=f"residual {lab}"
        )
        ax[1].semilogx(
            g[f"band_centre_{lab}_hz"],
            g[f"whitened_power_{lab}"],
            "o-" if lab == "after" else "s--",
            color=c,
            ms=3,
            label=f"whitened power {lab}",
        )
        if force:
            ax[2].plot(
                t,
                g[f"force_residual_{lab}_n"] * 1e3,
                color=c,
                lw=0.5,
                label=f"force residual {lab}",
            )
    ax[1].axhline(2.0, color="0.5", lw=0.8, ls=":")
    _marks(ax[0], g.get("marks", ()), scale=1e3, time=True)
    _marks(ax[1], g.get("marks", ()))
    ax[0].set_ylabel("fe residual [nm]")
    ax[0].set_xlabel("time [ms]")
    ax[1].set_ylabel("|whitened|^2 per bin\n(noise: 2)")
    ax[1].set_xlabel("frequency [Hz]")
    if force:
        ax[2].set_ylabel("force residual [mN]")
        ax[2].set_xlabel("time [ms]")
        ax[2].legend(fontsize=8)
    ax[0].legend(fontsize=8)
    ax[1].legend(fontsize=8)
    ax[0].set_title(f"{g['recording']}: measured minus simulated following error")
    return save(fig, path)


def _frf(g: dict, path: Path) -> Path:
    fig, ax = figure(2, 1, figsize=(8, 6), sharex=True)
    f = g["frequency_hz"]
    ax[0].loglog(f, np.abs(g["measured"]), "k.", ms=2, label="measured")
    ax[1].semilogx(f, np.degrees(np.angle(g["measured"])), "k.", ms=2)
    for lab, st in (("before", "C0--"), ("after", "C3-")):
        h = g[lab]
        ax[0].loglog(f, np.abs(h), st, lw=1.1, label=lab)
        ax[1].semilogx(f, np.degrees(np.angle(h)), st, lw=1.1)
    for a in ax:
        _marks(a, g.get("marks", ()))
    ax[0].set_ylabel("magnitude")
    ax[1].set_ylabel("phase [deg]")
    ax[1].set_xlabel("frequency [Hz]")
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"{g['recording']} ({g['frf_kind']})")
    return save(fig, path)


def _map(g: dict, path: Path) -> Path:
    fig, ax = figure(1, 2, figsize=(11, 4.5))
    for a, lab in ((ax[0], "before"), (ax[1], "after")):
        img = g[f"residual_{lab}_m"] * 1e9
        lim = np.nanpercentile(np.abs(img), 99) or 1.0
        im = a.imshow(img, cmap="RdBu_r", vmin=-lim, vmax=lim, origin="upper")
        a.set_title(f"{g['recording']}: residual {lab} [nm]")
        fig.colorbar(im, ax=a, shrink=0.8)
    return save(fig, path)


def _profile(g: dict, path: Path) -> Path:
    fig, ax = figure(figsize=(9, 3.5))
    for lab, c in (("before", "C0"), ("after", "C3")):
        ax.plot(
            g[f"position_{lab}_m"] * 1e3,
            g[f"residual_{lab}_m"] * 1e9,
            ".",
            ms=1,
            color=c,
            label=lab,
        )
    ax.set_xlabel("position along the profile [mm]")
    ax.set_ylabel("residual [nm]")
    ax.legend(fontsize=8, markerscale=6)
    ax.set_title(f"{g['recording']}: measured minus model")
    return save(fig, path)


_DRAW = {
    "spectrum": _spectrum,
    "residual": _residual,
    "frf": _frf,
    "map": _map,
    "profile": _profile,
}


def diagnosis_figures(
    figure_data: dict[str, dict], out_dir: str | Path
) -> dict[str, Path]:
    """Draw the before/after pictures of a diagnosis as PNG files.

    Parameters
    ----------
    figure_data : dict of str to dict
        Picture name (file stem) -> data, as :func:`servosurf.diagnose.figure_data`
        returns: ``kind`` (one of ``spectrum``, ``residual``, ``frf``, ``map``,
        ``profile``), ``recording`` (label), optional ``marks`` and the SI arrays
        of that kind.
    out_dir : str or Path
        Existing output directory; ``<name>.png`` is written into it.

    Returns
    -------
    dict of str to Path
        Picture name -> PNG file.

    Raises
    ------
    ValueError
        When a picture's ``kind`` is not one of the kinds above.
    """
    out_dir = Path(out_dir)
    res: dict[str, Path] = {}
    for name, g in figure_data.items():
        kind = g.get("kind")
        if kind not in _DRAW:
            raise ValueError(
                f"diagnosis figure {name!r}: unknown kind {kind!r} "
                f"(kinds: {', '.join(KINDS)})"
            )
        res[name] = _DRAW[kind](g, out_dir / f"{name}.png")
    return res
