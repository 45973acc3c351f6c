"""The table of seed-paper numbers that servosurf reproduces.

Each row: ``{"quantity", "paper", "servosurf", "unit", "tolerance", "within",
"setup"}``. ``tolerance`` is a string (``"15%"``, ``"3 deg"``, ``"0.2..0.8"``);
``within`` is the boolean check. Row groups register with :func:`row_group`, so other
stages (surface simulation) add their rows to the same table.

Reading of "bandwidth": every bandwidth in this table is the **open-loop crossover**.
With that reading one calibration reproduces the optima, the 1.6 kHz stability
limit, the 100 Hz overshoot and the force lag; the closed-loop -3 dB bandwidths that
go with them are listed in ``notes``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["Row", "row_group", "paper_table", "GROUPS"]


@dataclass(frozen=True)
class Row:
    """One reproduced number (SI units unless ``unit`` says otherwise)."""

    quantity: str
    paper: Any
    servosurf: Any
    unit: str
    tolerance: str
    within: bool
    setup: str = ""

    def as_dict(self) -> dict[str, Any]:
        """Plain dictionary for JSON."""
        return asdict(self)


#: Registered row producers: name -> callable(context) -> (rows, notes).
GROUPS: dict[str, Callable[[dict], tuple[list[Row], list[str]]]] = {}


def row_group(name: str):
    """Register a function producing rows for the paper table."""

    def deco(fn):
        GROUPS[name] = fn
        return fn

    return deco


def rel_row(
    quantity: str, paper: float, value: float, unit: str, rtol: float, setup: str = ""
) -> Row:
    """A row checked to a relative tolerance."""
    ok = bool(np.isfinite(value) and abs(value - paper) <= rtol * abs(paper))
    return Row(quantity, paper, float(value), unit, f"{rtol * 100:g}%", ok, setup)


def abs_row(
    quantity: str, paper: float, value: float, unit: str, atol: float, setup: str = ""
) -> Row:
    """A row checked to an absolute tolerance."""
    ok = bool(np.isfinite(value) and abs(value - paper) <= atol)
    return Row(quantity, paper, float(value), unit, f"+-{atol:g} {unit}", ok, setup)


def range_row(
    quantity: str,
    paper: float,
    value: float,
    unit: str,
    lo: float,
    hi: float,
    setup: str = "",
) -> Row:
    """A row checked to lie in ``[lo, hi]``."""
    ok = bool(np.isfinite(value) and lo <= value <= hi)
    return Row(quantity, paper, float(value), unit, f"{lo:g}..{hi:g} {unit}", ok, setup)


@row_group("servo")
def servo_rows(ctx: dict) -> tuple[list[Row], list[str]]:
    """Rows of the positioning-error study (paper sections 3.3, 5.1, 5.2, 5.3)."""
    from ..noise import optimal_bandwidth, stability_limit, synthesize
    from ..servo import ServoLoop, load_machine

    machine = ctx.get("machine") or load_machine()
    rows: list[Row] = []
    notes: list[str] = []
    a = machine.with_disturbances("section-3.3")
    b = machine.with_disturbances("section-5.2")
    sa = "disturbances section-3.3 (fitted to Figs 9-10)"
    sb = "disturbances section-5.2 (fitted to Figs 12-14)"
    for mass, paper in ((0.075, 874.0), (0.175, 468.0)):
        bw, _ = optimal_bandwidth(a.with_moving_mass(mass))
        rows.append(
            rel_row(
                f"optimal bandwidth (real error), {mass} kg", paper, bw, "Hz", 0.15, sa
            )
        )
    for mass, paper in ((0.075, 874.0), (0.175, 468.0)):
        bw, _ = optimal_bandwidth(b.with_moving_mass(mass), which="following")
        rows.append(
            rel_row(
                f"optimal bandwidth (following error), {mass} kg",
                paper,
                bw,
                "Hz",
                0.15,
                sb,
            )
        )
    for mass, paper in ((0.075, 0.182e-9), (0.175, 0.155e-9)):
        loop = ServoLoop(a.with_moving_mass(mass).with_bandwidth(468.0))
        rows.append(
            rel_row(
                f"RMS real error at 468 Hz, {mass} kg",
                paper,
                synthesize(loop).rms_real(),
                "m",
                0.15,
                sa,
            )
        )
    loop = ServoLoop(b.with_moving_mass(0.175).with_bandwidth(468.0))
    bud = synthesize(loop)
    rows.append(
        rel_row(
            "RMS following error at 468 Hz, 0.175 kg",
            0.83e-9,
            bud.rms_following(),
            "m",
            0.15,
            sb,
        )
    )
    rows.append(
        rel_row(
            "RMS real error at 468 Hz, 0.175 kg", 0.23e-9, bud.rms_real(), "m", 0.15, sb
        )
    )
    notes.append(
        "The paper's 0.155 nm (section 3.3) and 0.23 nm (section 5.2) real-error RMS "
        "at 468 Hz, 0.175 kg disagree; no single disturbance calibration gives both. "
        f"Under section-5.2 the real RMS at 468 Hz is {bud.rms_real() * 1e9:.3f} nm; "
        "under section-3.3 it is the 0.155 nm row."
    )
    heavy = b.with_moving_mass(0.175)
    lim = stability_limit(heavy)
    rows.append(
        rel_row(
            "stability limit (crossover), 0.175 kg",
            1600.0,
            lim,
            "Hz",
            0.10,
            "tuned PIDF, 60 deg margin",
        )
    )
    l3 = ServoLoop(heavy.with_bandwidth(lim * 0.999)).margins()["bandwidth_3db_hz"]
    notes.append(
        f"At the stability limit the closed-loop -3 dB bandwidth is {l3:.0f} Hz "
        "(reading 1.6 kHz as a -3 dB bandwidth would not match)."
    )
    loop = ServoLoop(heavy.with_bandwidth(1448.0))
    bud = synthesize(loop)
    peaks = bud.peaks()
    for paper, val in zip(
        (7400.0, 11700.0), peaks + [float("nan")] * (2 - len(peaks)), strict=False
    ):
        rows.append(
            rel_row(
                f"real-error spectrum peak near {paper / 1e3:g} kHz",
                paper,
                val,
                "Hz",
                0.03,
                "1448 Hz, 0.175 kg (Fig. 13c)",
            )
        )
    fr = loop.frf(np.array([100.0]))
    lag = -float(np.degrees(np.angle(fr.paths[("force", "sensor")][0])))
    rows.append(
        abs_row(
            "force-to-sensor phase lag at 100 Hz",
            12.0,
            lag,
            "deg",
            3.0,
            "1448 Hz, 0.175 kg (Fig. 17a)",
        )
    )
    ov = float(20 * np.log10(abs(fr.paths[("reference", "sensor")][0])))
    rows.append(
        range_row(
            "closed-loop overshoot at 100 Hz",
            0.6,
            ov,
            "dB",
            0.2,
            0.8,
            "1448 Hz, 0.175 kg; paper text 0.6 dB, 5.2/5 um = 0.34 dB",
        )
    )
    mg = loop.margins()
    notes.append(
        f"At 1448 Hz crossover (0.175 kg): closed-loop -3 dB bandwidth "
        f"{mg['bandwidth_3db_hz']:.0f} Hz, phase margin "
        f"{mg['phase_margin_deg']:.1f} deg, gain margin {mg['gain_margin_db']:.1f} dB."
    )
    for bwx in (468.0, 874.0):
        m3 = ServoLoop(heavy.with_bandwidth(bwx)).margins()["bandwidth_3db_hz"]
        notes.append(
            f"{bwx:g} Hz crossover (0.175 kg) = {m3:.0f} Hz closed-loop -3 dB."
        )
    return rows, notes


def paper_table(
    groups: tuple[str, ...] | None = None, *, machine=None, progress=None
) -> dict[str, Any]:
    """Compute every registered row group.

    Parameters
    ----------
    groups : tuple of str, optional
        Names from :data:`GROUPS`; default all.
    machine : Machine, optional
        Machine to evaluate (default: the built-in seed prototype).
    progress : callable, optional
        ``progress(name)`` context manager per group (stderr stage lines).

    Returns
    -------
    dict
        ``{"rows": [...], "notes": [...], "reported": [...]}``; ``reported`` holds
        numbers the paper gives without a pass/fail tolerance (measured values the
        model is not expected to reach, such as the flat-face Ra).
    """
    from contextlib import nullcontext

    names = groups or tuple(GROUPS)
    ctx = {"machine": machine}
    rows: list[dict] = []
    notes: list[str] = []
    for name in names:
        with progress(name) if progress else nullcontext():
            r, n = GROUPS[name](ctx)
        rows.extend(x.as_dict() for x in r)
        notes.extend(n)
    return {"rows": rows, "notes": notes, "reported": ctx.get("reported", [])}


def _nearest(values: list[float], target: float) -> float:
    return min(values, key=lambda v: abs(v - target)) if values else float("nan")


@row_group("surface")
def surface_rows(ctx: dict) -> tuple[list[Row], list[str]]:
    """Rows of the lenslet and flat cuts (paper sections 4.2, 5.3, Table 2)."""
    from pathlib import Path

    from ..simulation import simulate
    from ..toolpath import load_toolpath
    from ._simulation import analyse

    machine = ctx.get("machine")
    from ..toolpath import builtin_toolpaths

    # the built-in toolpaths ship with the package: found from any folder
    tp_dir = Path(ctx.get("toolpaths") or builtin_toolpaths()["lenslet_5um"].parent)
    rows: list[Row] = []
    notes: list[str] = []
    reported = ctx.setdefault("reported", [])
    setup = "1448 Hz crossover, 0.175 kg, seed 0"
    kw = {"machine": machine, "bandwidth": 1448.0, "mass": 0.175, "seed": 0}
    r5 = simulate(tp_dir / "lenslet_5um.toml", **kw)
    a5 = analyse(r5)
    pk = a5["spectrum_peaks_per_m"][:3]
    for paper in (170e3, 255e3):
        rows.append(
            rel_row(
                f"5 um lenslet spectral peak near {paper / 1e3:g} mm^-1",
                paper,
                _nearest(pk, paper),
                "1/m",
                0.05,
                setup,
            )
        )
    notes.append(
        "The paper's own numbers disagree on the second vibration: its model puts the "
        "real-error peaks at 7.4 and 11.7 kHz (Fig. 13c), which at 42.3 mm/s are 175 "
        "and 277 mm^-1, while its 5 um surface shows 170 and 255 mm^-1 (7.2 and 10.8 "
        "kHz) and its 10 um surface 6.6 and 11.5 kHz. servosurf keeps the 7.4/11.7 kHz "
        f"modes of section 5.2; its 5 um surface peaks are "
        f"{', '.join(f'{p / 1e3:.0f}' for p in pk)} mm^-1."
    )
    rows.append(
        rel_row(
            "5 um lenslet: max tool deviation from the cutting force",
            295e-9,
            a5["deviation_max_m"],
            "m",
            0.15,
            setup + " (Fig. 17b)",
        )
    )
    rows.append(
        Row(
            "5 um lenslet: deviation peak lags the force peak",
            "lags",
            a5["deviation_lag_s"],
            "s",
            "> 0",
            bool(a5["deviation_lag_s"] > 0),
            setup,
        )
    )
    rows.append(
        rel_row(
            "5 um lenslet: overshoot after the cut (paper simulation)",
            180e-9,
            a5["deviation_overshoot_m"],
            "m",
            0.30,
            setup,
        )
    )
    reported.append(
        {
            "quantity": "5 um lenslet: overshoot after the cut (paper measured)",
            "paper": 34e-9,
            "servosurf": a5["deviation_overshoot_m"],
            "unit": "m",
            "comment": "the measured 34 nm is a following error, in which the "
            "sensor sees the carrier (m2), not the tool",
        }
    )
    rows.append(
        rel_row(
            "5 um lenslet: maximum form error",
            200e-9,
            a5["form_error_max_m"],
            "m",
            0.30,
            setup + ", reference = air-cut amplitude",
        )
    )
    rows.append(
        Row(
            "5 um lenslet: maximum form error lags the deepest point",
            "lags",
            a5["form_error_lag_m"],
            "m",
            "> 0",
            bool(a5["form_error_lag_m"] > 0),
            setup,
        )
    )
    r10 = simulate(tp_dir / "lenslet_10um.toml", **kw)
    a10 = analyse(r10)
    hz10 = a10["spectrum_peaks_hz"][:3]
    for paper in (6.6e3, 11.5e3):
        rows.append(
            rel_row(
                f"10 um lenslet vibration peak near {paper / 1e3:g} kHz",
                paper,
                _nearest(hz10, paper),
                "Hz",
                0.15,
                setup + f", {a10['surface_speed_m_per_s'] * 1e3:.1f} mm/s",
            )
        )
    notes.append(
        "10 um lenslet peaks are compared within 15 %: the paper's own two "
        "lenslets put the same first mode 11 % apart (7.2 and 6.6 kHz)."
    )
    # flat face: roughness by model part (no fudge term), the one flat-face Ra
    # definition (report.flat_face_ra: the toolpath's whole field, no filter)
    spec = load_toolpath(tp_dir / "flat_facing.toml")
    feed, rad = spec.path.feed_per_rev, spec.tool.nose_radius
    ra_kin = feed**2 / (18 * np.sqrt(3) * rad)
    parts_sets = {
        "kinematic": (),
        "kinematic+force": ("tracking", "force"),
        "kinematic+vibration": ("tracking", "vibration"),
        "all": ("tracking", "force", "vibration"),
    }
    ra = {}
    for name, parts in parts_sets.items():
        res = simulate(spec, parts=parts, **kw)
        ra[name] = analyse(res)["ra_m"]
    rows.append(
        rel_row(
            "flat face Ra, kinematic only, vs f^2/(18 sqrt(3) R)",
            ra_kin,
            ra["kinematic"],
            "m",
            0.01,
            "2 um/rev, R 0.5 mm",
        )
    )
    for name, v in ra.items():
        reported.append(
            {
                "quantity": f"flat face Ra, model parts: {name}",
                "paper": 1.2e-9,
                "servosurf": v,
                "unit": "m",
                "comment": "paper: measured, no filter; no fudge term added",
            }
        )
    notes.append(
        f"Flat Ra: kinematic {ra['kinematic'] * 1e9:.3f} nm, +force "
        f"{ra['kinematic+force'] * 1e9:.3f} nm, +vibration "
        f"{ra['kinematic+vibration'] * 1e9:.3f} nm, all {ra['all'] * 1e9:.3f} nm "
        "against 1.2 nm measured: the gap is physics the model leaves out (material "
        "side flow, elastic recovery, tool edge, spindle), for `servosurf diagnose` "
        "to locate."
    )
    return rows, notes
