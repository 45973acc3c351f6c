"""Static figures of height maps, form error profiles and spectra (matplotlib, Agg).

matplotlib is imported inside each function (never on ``import servosurf``) and
figures are drawn on an Agg canvas without pyplot, so no global state or GUI
back-end is touched. Every figure is written atomically: to a temporary file in
the destination folder, then moved into place with :func:`os.replace`.

Display units appear only here: heights in nm or um, lateral positions in um,
spatial frequencies in 1/mm. Inputs are SI (m, 1/m, m^3, m/s).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError

if TYPE_CHECKING:
    from ..metrology import Surface

__all__ = [
    "plot_map",
    "plot_profile_with_form_error",
    "plot_spectrum",
    "plot_filtered_map",
]

#: Height display units: name -> metres per unit.
HEIGHT_UNITS: dict[str, float] = {"nm": 1e-9, "um": 1e-6}

_UNIT_LABEL = {"nm": "nm", "um": "\u00b5m"}


def _new_figure(figsize: tuple[float, float]) -> Any:
    """Return a matplotlib Figure attached to an Agg canvas (no pyplot)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        raise ImportError(
            "servosurf plots need matplotlib: pip install servosurf[viz]"
        ) from None
    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save_atomic(fig: Any, path: str | os.PathLike[str], dpi: int) -> Path:
    """Write ``fig`` as PNG to ``path`` via a temporary file and os.replace."""
    from .._atomic import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return Path(path)


def _unit(unit: str) -> float:
    if unit not in HEIGHT_UNITS:
        raise ConfigError(f"unit must be one of {sorted(HEIGHT_UNITS)}, got {unit!r}")
    return HEIGHT_UNITS[unit]


def _draw_map(
    fig: Any, ax: Any, surface: Surface, unit: str, title: str | None,
    robust: float | None = None,
) -> None:
    scale = _unit(unit)
    ny, nx = surface.shape
    if surface.calibrated:
        x, y = surface.coords()
        dx, dy = surface.dx, surface.dy
        extent = [
            (x[0] - dx / 2) * 1e6,
            (x[-1] + dx / 2) * 1e6,
            (y[-1] + dy / 2) * 1e6,
            (y[0] - dy / 2) * 1e6,
        ]
        xlabel, ylabel = "x (\u00b5m)", "y (\u00b5m)"
    else:
        extent = [-0.5, nx - 0.5, ny - 0.5, -0.5]
        xlabel, ylabel = "x (pixel)", "y (pixel)"
    width, height = abs(extent[1] - extent[0]), abs(extent[2] - extent[3])
    # true aspect unless the map is a thin strip, which would vanish
    aspect = "equal" if 0.1 <= height / width <= 10.0 else "auto"
    data = np.ma.masked_invalid(surface.z / scale)
    vmin = vmax = None
    extend = "neither"
    label = f"height ({_UNIT_LABEL[unit]})"
    if robust is not None and data.count() > 1:
        vmin, vmax = np.percentile(data.compressed(), [robust, 100.0 - robust])
        if not vmax > vmin:
            vmin = vmax = None
        else:
            below = bool((data < vmin).any())
            above = bool((data > vmax).any())
            extend = {(True, True): "both", (True, False): "min",
                      (False, True): "max"}.get((below, above), "neither")
            label += f", colours {robust:g}-{100 - robust:g} percentile"
    im = ax.imshow(
        data,
        extent=extent,
        origin="upper",
        aspect=aspect,
        cmap="viridis",
        # a map with more pixels than the PNG is low-pass filtered before it is
        # resampled (no moire of the display's own decimation); smaller: nearest
        interpolation="antialiased",
        vmin=vmin,
        vmax=vmax,
    )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    cb = fig.colorbar(im, ax=ax, extend=extend)
    cb.formatter.set_useOffset(False)  # read heights directly, no "-4.999e3" offset
    cb.set_label(label)


def plot_map(
    surface: Surface,
    path: str | os.PathLike[str],
    *,
    title: str | None = None,
    unit: str = "nm",
    dpi: int = 120,
    robust: float | None = None,
) -> Path:
    """Write a height map image with a colour bar to a PNG file.

    Parameters
    ----------
    surface : Surface
        Height map in m (rows = y, row 0 at the top); NaN pixels are left blank.
    path : str or path-like
        Destination PNG file; its folder is created if needed.
    title : str or None, default: None
        Figure title.
    unit : {"nm", "um"}, default: "nm"
        Height unit of the colour bar.
    dpi : int, default: 120
        Resolution of the PNG, in dots per inch.
    robust : float or None, default: None
        Percentile p (0 <= p < 50): the colour scale spans the p-th to the
        (100 - p)-th percentile of the valid heights, so that a few outliers (a
        filter's rim artefact) do not set it; heights beyond are drawn in the end
        colours and the colour bar shows arrows. None: the full range.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        If ``unit`` is unknown or ``robust`` is outside [0, 50).

    Notes
    -----
    Axes are in um when the map is calibrated, in pixels otherwise.
    """
    _unit(unit)
    if robust is not None and not (0.0 <= float(robust) < 50.0):
        raise ConfigError(f"robust must be a percentile in [0, 50), got {robust!r}")
    fig = _new_figure((6.0, 4.8))
    ax = fig.add_subplot()
    _draw_map(fig, ax, surface, unit, title, robust)
    return _save_atomic(fig, path, dpi)


def plot_filtered_map(
    surface: Surface,
    filtered: Surface,
    path: str | os.PathLike[str],
    *,
    cutoff: float | None = None,
    title: str | None = None,
    unit: str = "nm",
    dpi: int = 120,
) -> Path:
    """Write a side-by-side PNG of a map and its filtered version.

    Parameters
    ----------
    surface : Surface
        Original height map, in m.
    filtered : Surface
        Filtered map (for example ``high_pass(surface, 1 / 80e3)``), in m.
    path : str or path-like
        Destination PNG file.
    cutoff : float or None, default: None
        Cut-off wavelength used, in m; shown in the right panel's title as a
        spatial frequency in 1/mm and a wavelength in um.
    title : str or None, default: None
        Figure title.
    unit : {"nm", "um"}, default: "nm"
        Height unit of both colour bars.
    dpi : int, default: 120
        Resolution of the PNG, in dots per inch.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        If ``unit`` is unknown.
    """
    _unit(unit)
    fig = _new_figure((11.0, 4.6))
    ax1, ax2 = fig.subplots(1, 2)
    _draw_map(fig, ax1, surface, unit, "original")
    if cutoff is not None:
        sub = (
            f"filtered: {1e-3 / cutoff:.4g} mm\u207b\u00b9 "
            f"({cutoff * 1e6:.4g} \u00b5m) cut-off"
        )
    else:
        sub = "filtered"
    _draw_map(fig, ax2, filtered, unit, sub)
    if title:
        fig.suptitle(title)
    return _save_atomic(fig, path, dpi)


def plot_profile_with_form_error(
    x: np.ndarray,
    z: np.ndarray,
    z_nominal: np.ndarray,
    err: np.ndarray,
    path: str | os.PathLike[str],
    *,
    title: str | None = None,
    dpi: int = 120,
    xlabel: str = "x (\u00b5m)",
    label: str = "measured",
    nominal_label: str = "nominal",
) -> Path:
    """Write a two-panel PNG: profile with its nominal, and the form error.

    Parameters
    ----------
    x : ndarray of shape (n,)
        Positions along the profile, in m.
    z : ndarray of shape (n,)
        Measured heights, in m (shown in um).
    z_nominal : ndarray of shape (n,)
        Aligned nominal (reference) heights, in m (shown in um).
    err : ndarray of shape (n,)
        Form error ``z - z_nominal``, in m (shown in nm); NaN where not evaluated.
    path : str or path-like
        Destination PNG file.
    title : str or None, default: None
        Figure title.
    dpi : int, default: 120
        Resolution of the PNG, in dots per inch.
    xlabel : str, default: "x (µm)"
        Label of the position axis (name the axis the profile runs along).
    label : str, default: "measured"
        Legend entry of ``z`` (e.g. "simulated").
    nominal_label : str, default: "nominal"
        Legend entry of ``z_nominal``.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        If the arrays differ in length.
    """
    arrays = [np.asarray(a, dtype=float).ravel() for a in (x, z, z_nominal, err)]
    if len({a.size for a in arrays}) != 1:
        raise ConfigError(
            "x, z, z_nominal and err must have the same length, got "
            f"{[a.size for a in arrays]}"
        )
    x, z, zn, e = arrays
    fig = _new_figure((7.0, 5.6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(x * 1e6, z * 1e6, lw=1.0, label=label)
    ax1.plot(x * 1e6, zn * 1e6, lw=1.0, ls="--", label=nominal_label)
    ax1.set_ylabel("height (\u00b5m)")
    ax1.legend(loc="lower left", fontsize=8)
    ax2.plot(x * 1e6, e * 1e9, lw=1.0, color="C3")
    ax2.axhline(0.0, color="0.5", lw=0.5)
    if np.isfinite(e).any():
        k = int(np.nanargmax(np.abs(e)))
        ax2.plot([x[k] * 1e6], [e[k] * 1e9], "o", color="C3")
        ax2.annotate(
            f"max {abs(e[k]) * 1e9:.0f} nm",
            (x[k] * 1e6, e[k] * 1e9),
            textcoords="offset points",
            xytext=(5, 5),
        )
    ax2.set_xlabel(xlabel)
    ax2.set_ylabel("form error (nm)")
    if title:
        fig.suptitle(title)
    return _save_atomic(fig, path, dpi)


def plot_spectrum(
    freq: np.ndarray,
    psd: np.ndarray,
    peaks: Sequence[dict[str, Any]],
    path: str | os.PathLike[str],
    *,
    speed: float | None = None,
    title: str | None = None,
    dpi: int = 120,
    fmin: float | None = None,
) -> Path:
    """Write a log-PSD plot against spatial frequency with every peak labelled.

    Parameters
    ----------
    freq : ndarray of shape (m,)
        Spatial frequency, in 1/m (shown in 1/mm).
    psd : ndarray of shape (m,)
        One-sided PSD, in m^3 (shown in nm^2 mm).
    peaks : sequence of dict
        Peaks from :func:`servosurf.metrology.find_peaks_spectrum` (uses
        ``freq_per_m`` and ``psd_m3``); may be empty. Every one is marked and
        labelled; labels of neighbouring peaks are staggered so they do not overlap.
    path : str or path-like
        Destination PNG file.
    speed : float or None, default: None
        Surface speed in m/s; when given each label also shows the equivalent
        temporal frequency ``freq * speed`` in kHz.
    title : str or None, default: None
        Figure title.
    dpi : int, default: 120
        Resolution of the PNG, in dots per inch.
    fmin : float or None, default: None
        Spatial frequency in 1/m below which the map was high-pass filtered (the
        band is shaded and named); peaks below it are drawn in grey.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        If ``freq`` and ``psd`` differ in shape or ``speed`` is not positive.
    """
    f = np.asarray(freq, dtype=float)
    p = np.asarray(psd, dtype=float)
    if f.shape != p.shape or f.ndim != 1:
        raise ConfigError(
            f"freq and psd must be 1-D of the same shape, got {f.shape} and {p.shape}"
        )
    if speed is not None and not (np.isfinite(speed) and speed > 0):
        raise ConfigError(f"speed must be > 0 in m/s, got {speed!r}")
    keep = (f > 0) & np.isfinite(p) & (p > 0)
    fig = _new_figure((7.0, 4.4))
    ax = fig.add_subplot()
    ax.semilogy(f[keep] * 1e-3, p[keep] * 1e21, lw=1.0)
    if fmin is not None and keep.any():
        ax.axvspan(0.0, fmin * 1e-3, color="0.9", zorder=0)
        band = f"high-passed\n< {fmin * 1e-3:g} mm\u207b\u00b9"
        ax.text(0.5 * fmin * 1e-3, 0.02, band, transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=7, color="0.4")
    notes = []
    for pk in sorted(peaks, key=lambda q: float(q["freq_per_m"])):
        fm = float(pk["freq_per_m"])
        pm = float(pk.get("psd_m3", np.interp(fm, f, p)))
        label = f"{fm * 1e-3:.0f} mm\u207b\u00b9"
        if speed is not None:
            label += f"\n{fm * speed * 1e-3:.2f} kHz"
        below = fmin is not None and fm < fmin
        ax.plot([fm * 1e-3], [pm * 1e21], "v", color="0.45" if below else "C3", ms=5)
        notes.append(ax.annotate(
            label, (fm * 1e-3, pm * 1e21), textcoords="offset points",
            xytext=(0, 8), ha="center", va="bottom", fontsize=8,
            color="0.45" if below else "black",
            arrowprops={"arrowstyle": "-", "color": "0.6", "lw": 0.5,
                        "shrinkA": 0, "shrinkB": 4},
        ))
    if title:
        ax.set_title(title)
    ax.set_xlabel("spatial frequency (mm\u207b\u00b9)")
    ax.set_ylabel("PSD (nm\u00b2 mm)")
    if notes:
        _place_labels(fig, ax, notes)
    return _save_atomic(fig, path, dpi)


def _place_labels(fig: Any, ax: Any, notes: list) -> None:
    """Lay out peak labels so that none overlaps another and all stay in the axes.

    Each label starts 8 points above its peak. Labels whose boxes would overlap
    side by side form a group: the group's labels sit side by side at one height,
    above the highest of their peaks, spread just enough not to touch and centred
    on their peaks; a thin line joins each label to its peak, and since labels
    keep the peaks' order and sit above them, the lines cross no label. When the
    highest label ends above the axes, the log y range grows and the layout is
    done again (at most four times).
    """
    from matplotlib.text import Text

    scale = 72.0 / fig.dpi  # display pixels -> points
    for _ in range(4):
        for a in notes:
            a.xyann = (0, 8)
        fig.canvas.draw()
        r = fig.canvas.get_renderer()
        items = []  # [peak x, peak y, width, height, bottom at rest]
        for a in notes:
            bb = Text.get_window_extent(a, r)
            px, py = ax.transData.transform(a.xy)
            items.append([px, py, bb.width, bb.height, bb.y0])
        groups = [[k] for k in range(len(items))]
        merged = True
        while merged:  # merge groups whose boxes touch until none do
            merged = False
            boxes = [_group_box(items, g) for g in groups]
            for a in range(len(groups)):
                for b in range(a + 1, len(groups)):
                    (l1, r1, b1, t1), (l2, r2, b2, t2) = boxes[a], boxes[b]
                    if l1 < r2 + 2 and l2 < r1 + 2 and b1 < t2 + 2 and b2 < t1 + 2:
                        groups[a] = sorted(groups[a] + groups.pop(b))
                        merged = True
                        break
                if merged:
                    break
        top = -np.inf
        for g in groups:
            left, _, bottom, _ = _group_box(items, g)
            x = left
            for k in g:
                px, py, w, h, rest = items[k]
                cx = x + w / 2 if len(g) > 1 else px
                x += w + 4.0
                notes[k].xyann = ((cx - px) * scale, 8 + (bottom - rest) * scale)
                top = max(top, bottom + h)
        box = ax.get_window_extent(r)
        if top <= box.y1 - 2:
            return
        lo, hi = ax.get_ylim()
        need = (top - box.y0 + 6) / max(box.height, 1.0)  # axes heights
        ax.set_ylim(lo, lo * (hi / lo) ** need)


def _group_box(items: list, group: list) -> tuple[float, float, float, float]:
    """Display box (left, right, bottom, top) of a label group laid side by side,
    centred on its peaks, above the highest of them."""
    if len(group) == 1:
        px, _, w, h, rest = items[group[0]]
        return px - w / 2, px + w / 2, rest, rest + h
    total = sum(items[k][2] for k in group) + 4.0 * (len(group) - 1)
    centre = float(np.mean([items[k][0] for k in group]))
    bottom = max(items[k][4] for k in group)
    height = max(items[k][3] for k in group)
    return centre - total / 2, centre + total / 2, bottom, bottom + height
