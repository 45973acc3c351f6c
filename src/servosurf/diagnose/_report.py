"""Files of a diagnosis and the data of its pictures: before/after residuals, FRFs,
maps.

Every picture shows the recording against the nominal model ("before") and the
fitted model ("after") and marks the located mismatch (bands, lines, time windows).
This module gathers that data in SI units (:func:`figure_data`);
:func:`servosurf.viz.diagnosis_figures` draws it.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np

from ._blocks import (
    CutBlock,
    ForceBlock,
    FRFBlock,
    PointsBlock,
    SpectralBlock,
    TimeBlock,
)
from ._locate import third_octaves
from .effects import Model

__all__ = ["figure_data", "fitted_effects_toml", "fitted_machine_toml", "write_figures"]


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def _marks(mism, rec: str) -> list[dict]:
    """The located mismatches of one recording, as figure marks (SI units).

    Each mark holds the keys of a mismatch's details the figures draw: ``t_s``
    (time window, s), ``band_hz`` (frequency band, Hz), ``frequency_hz`` (a line).
    """
    keys = ("t_s", "band_hz", "frequency_hz")
    out = []
    for m in mism:
        if m.recording != rec:
            continue
        mark = {k: m.details[k] for k in keys if k in m.details}
        if mark:
            out.append(mark)
    return out


def _bands(freq, val):
    e = third_octaves(freq[0], freq[-1] * 1.0001)
    idx = np.digitize(freq, e) - 1
    nb = e.size - 1
    cnt = np.bincount(idx, minlength=nb)[:nb]
    s = np.bincount(idx, weights=val, minlength=nb)[:nb]
    ok = cnt > 0
    fc = np.sqrt(e[:-1] * e[1:])
    return fc[ok], s[ok] / cnt[ok]


def _spectrum(b: SpectralBlock, d) -> dict:
    return {
        "kind": "spectrum",
        "recording": b.recording,
        "records": int(b.nrec),
        "frequency_hz": b.freq,
        "measured_m2_per_hz": b.pbar,
        "before_m2_per_hz": b.expected(Model()),
        "after_m2_per_hz": b.expected(d.model),
        "marks": _marks(d.mismatches, b.recording),
    }


def _timeseries(b: TimeBlock, d, force: ForceBlock | None) -> dict:
    n = b.records[0]["fe"].size
    t = b.records[0].get("t0", 0.0) + np.arange(n) / b.fs
    if isinstance(b, CutBlock):
        t = (b.k0 + np.arange(n)) / b.fs
    out = {
        "kind": "residual",
        "recording": b.recording,
        "time_s": t,
        "marks": _marks(d.mismatches, b.recording),
    }
    for p, lab in ((Model(), "before"), (d.model, "after")):
        out[f"residual_{lab}_m"] = b.residual_time(p, 0)
        _, _w, f = b.meta[0]
        fc, e = _bands(f, np.abs(b.whitened(p, 0)) ** 2)
        out[f"band_centre_{lab}_hz"] = fc
        out[f"whitened_power_{lab}"] = e
        if force is not None:
            out[f"force_residual_{lab}_n"] = (
                force.force - force.cut.predict(p)["force"])
    return out


def _frf(b: FRFBlock, d) -> dict:
    out = {
        "kind": "frf",
        "recording": b.recording,
        "frf_kind": b.kind,
        "frequency_hz": b.freq,
        "measured": b.frf,
        "marks": _marks(d.mismatches, b.recording),
    }
    for p, lab in ((Model(), "before"), (d.model, "after")):
        out[lab] = b.model(p) * (b.gain_offset(p) if b.gain else 1.0)
    return out


def _points(b: PointsBlock, d, nominal: PointsBlock | None) -> dict:
    s_nom = nominal or b
    before = s_nom.nuisance_fit(Model())
    after = b.nuisance_fit(d.model)
    if b.kind == "surface" and b.grid is not None:
        shape, flat = b.grid
        out = {"kind": "map", "recording": b.recording}
        for vals, keep, lab in ((before, s_nom.keep, "before"),
                                (after, b.keep, "after")):
            img = np.full(shape[0] * shape[1], np.nan)
            img[flat[keep]] = vals
            out[f"residual_{lab}_m"] = img.reshape(shape)
        return out
    out = {"kind": "profile", "recording": b.recording}
    for vals, blk, lab in ((before, s_nom, "before"), (after, b, "after")):
        pos = blk.along[blk.keep] if blk.along is not None else np.arange(vals.size)
        out[f"position_{lab}_m"] = pos
        out[f"residual_{lab}_m"] = vals
    return out


def figure_data(d) -> dict[str, dict]:
    """The data of the before/after pictures of a :class:`Diagnosis`.

    "Before" is the nominal model, "after" the fitted one; every array is in SI
    units (m, s, Hz, N; spectra in m^2/Hz) and
    :func:`servosurf.viz.diagnosis_figures` draws them.

    Parameters
    ----------
    d : Diagnosis
        A finished diagnosis.

    Returns
    -------
    dict of str to dict
        Picture name (a file stem) -> its data: ``kind`` (``spectrum``,
        ``residual``, ``frf``, ``map`` or ``profile``), ``recording``, ``marks``
        (located mismatches: ``t_s``, ``band_hz`` or ``frequency_hz``) and the
        curves of that kind.
    """
    res: dict[str, dict] = {}
    nominal = {id(b): n for b, n in zip(d.blocks, d.blocks_nominal, strict=True)}
    forces = {b.cut.recording: b for b in d.blocks if isinstance(b, ForceBlock)}
    for b in d.blocks:
        name = _safe(b.recording)
        if isinstance(b, SpectralBlock):
            res[f"{name}_spectrum"] = _spectrum(b, d)
        elif isinstance(b, TimeBlock):
            res[f"{name}_residual"] = _timeseries(b, d, forces.get(b.recording))
        elif isinstance(b, FRFBlock):
            res[f"{name}_frf"] = _frf(b, d)
        elif isinstance(b, PointsBlock):
            key = f"{name}_{'map' if b.kind == 'surface' else 'profile'}"
            res[key] = _points(b, d, nominal.get(id(b)))
    return res


def write_figures(d, out: str | Path) -> dict[str, Path]:
    """Write the before/after pictures of a :class:`Diagnosis` into ``out``.

    Parameters
    ----------
    d : Diagnosis
        A finished diagnosis.
    out : str or Path
        Existing output directory.

    Returns
    -------
    dict of str to Path
        Picture name -> PNG file.
    """
    from ..viz import diagnosis_figures

    return diagnosis_figures(figure_data(d), out)


def fitted_machine_toml(d) -> str:
    """Machine TOML of the fitted model (``Machine.to_toml``).

    What a machine file can hold is written into it: the loop perturbation (delay,
    recalibrated parameters), the machine hooks (disturbance PSDs) and the loop's
    current limit; the controller gains are written explicitly so that
    ``simulate`` and ``noise`` keep the installed controller. Effects a machine file
    cannot hold (modes, nonlinearities, tool and map terms) are listed in the
    header and in ``fitted-effects.toml``.
    """
    case = d.case
    p = d.model
    m = case.machine_for(p)
    pidf = case.pidf
    c = dataclasses.replace(
        m.controller, kp=pidf.kp, ki=pidf.ki, kd=pidf.kd, tf=pidf.tf
    )
    m = dataclasses.replace(m, controller=c,
                            disturbances=case.hooked_machine(p).disturbances)
    i_max = case.nonlinearity(p).max_current
    if math.isfinite(i_max):
        m = dataclasses.replace(
            m,
            actuator=dataclasses.replace(m.actuator, max_current=float(i_max)),
        )
    lines = [
        f"fitted by servosurf diagnose to {d.manifest.path if d.manifest else ''}",
        f"verdict: {d.verdict}",
    ]
    for e in d.explanations + d.recalibration:
        pars = ", ".join(f"{k} = {v:.6g}" for k, v in e["parameters"].items())
        lines.append(f"{e['effect']}: {pars}")
    lines.append("effects without a machine key are in fitted-effects.toml")
    return m.to_toml(header="\n".join(lines))


def fitted_effects_toml(d) -> str:
    """Every term of the fitted model as TOML (SI, unit-suffixed keys).

    One table per effect (an array of tables for effects with several terms),
    keys as in the JSON report; ``servosurf.diagnose.effects`` documents them.
    """
    from ..config import dump_toml

    effects = {t.effect.name: t.effect for t in d.terms}
    out: dict = {}
    for name in d.model.names:
        eff = effects[name]
        rows = [
            {k.replace("_", "-"): v for k, v in eff.term(d.model, k_).report().items()}
            for k_ in range(eff.slots(d.model))
        ]
        out[name] = rows if eff.max_terms > 1 else rows[0]
    return dump_toml(
        {"effects": out},
        header="fitted catalogue effects (SI units), see servosurf.diagnose.effects",
    )
