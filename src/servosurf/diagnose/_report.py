"""Pictures and files of a diagnosis: before/after residuals, FRFs, maps.

Every picture shows the recording against the nominal model ("before") and the
fitted model ("after") and marks the located mismatch (bands, lines, time windows).
Display units (nm, ms, kHz, degree) are used here only.
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

__all__ = ["figures", "fitted_machine_toml", "fitted_effects_toml"]


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def _marks(ax, mism, rec, *, scale=1.0, time=False):
    for m in mism:
        if m.recording != rec:
            continue
        d = m.details
        if time and "t_s" in d:
            ax.axvspan(d["t_s"][0] * scale, d["t_s"][1] * scale, color="C3", alpha=0.15)
        elif not time and "band_hz" in d:
            ax.axvspan(
                d["band_hz"][0] * scale, d["band_hz"][1] * scale, color="C3", alpha=0.12
            )
        elif not time and "frequency_hz" in d:
            ax.axvline(d["frequency_hz"] * scale, color="C3", lw=0.8, ls=":")


def _bands(freq, val):
    e = third_octaves(freq[0], freq[-1] * 1.0001)
    idx = np.digitize(freq, e) - 1
    nb = e.size - 1
    cnt = np.bincount(idx, minlength=nb)[:nb]
    s = np.bincount(idx, weights=val, minlength=nb)[:nb]
    ok = cnt > 0
    fc = np.sqrt(e[:-1] * e[1:])
    return fc[ok], s[ok] / cnt[ok]


def _spectrum(b: SpectralBlock, d, path: Path) -> Path:
    from ..viz._common import figure, save

    fig, ax = figure(figsize=(8, 4.5))
    ax.loglog(b.freq, b.pbar, color="0.75", lw=0.6, label="measured (averaged)")
    for p, lab, st in (
        (Model(), "model before", "C0--"),
        (d.model, "after", "C3-"),
    ):
        ax.loglog(b.freq, b.expected(p), st, lw=1.2, label=lab)
    _marks(ax, d.mismatches, b.recording)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("following-error PSD [m^2/Hz]")
    ax.set_title(f"{b.recording}: idle following-error spectrum ({b.nrec} records)")
    ax.legend(fontsize=8)
    return save(fig, path)


def _timeseries(b: TimeBlock, d, force: ForceBlock | None, path: Path) -> Path:
    from ..viz._common import figure, save

    rows = 3 if force is not None else 2
    fig, ax = figure(rows, 1, figsize=(9, 2.6 * rows))
    n = b.records[0]["fe"].size
    t = (b.records[0].get("t0", 0.0) + np.arange(n) / b.fs) * 1e3
    if isinstance(b, CutBlock):
        t = (b.k0 + np.arange(n)) / b.fs * 1e3
    for p, lab, c in ((Model(), "before", "C0"), (d.model, "after", "C3")):
        r = b.residual_time(p, 0)
        ax[0].plot(t, r * 1e9, color=c, lw=0.5, label=f"residual {lab}")
        _, w, f = b.meta[0]
        x = b.whitened(p, 0)
        fc, e = _bands(f, np.abs(x) ** 2)
        ax[1].semilogx(
            fc,
            e,
            "o-" if lab == "after" else "s--",
            color=c,
            ms=3,
            label=f"whitened power {lab}",
        )
        if force is not None:
            ax[2].plot(
                t,
                (force.force - force.cut.predict(p)["force"]) * 1e3,
                color=c,
                lw=0.5,
                label=f"force residual {lab}",
            )
    ax[1].axhline(2.0, color="0.5", lw=0.8, ls=":")
    _marks(ax[0], d.mismatches, b.recording, scale=1e3, time=True)
    _marks(ax[1], d.mismatches, b.recording)
    ax[0].set_ylabel("fe residual [nm]")
    ax[0].set_xlabel("time [ms]")
    ax[1].set_ylabel("|whitened|^2 per bin\n(noise: 2)")
    ax[1].set_xlabel("frequency [Hz]")
    if force is not None:
        ax[2].set_ylabel("force residual [mN]")
        ax[2].set_xlabel("time [ms]")
        ax[2].legend(fontsize=8)
    ax[0].legend(fontsize=8)
    ax[1].legend(fontsize=8)
    ax[0].set_title(f"{b.recording}: measured minus simulated following error")
    return save(fig, path)


def _frf(b: FRFBlock, d, path: Path) -> Path:
    from ..viz._common import figure, save

    fig, ax = figure(2, 1, figsize=(8, 6), sharex=True)
    ax[0].loglog(b.freq, np.abs(b.frf), "k.", ms=2, label="measured")
    ax[1].semilogx(b.freq, np.degrees(np.angle(b.frf)), "k.", ms=2)
    for p, lab, st in ((Model(), "before", "C0--"), (d.model, "after", "C3-")):
        h = b.model(p) * (b.gain_offset(p) if b.gain else 1.0)
        ax[0].loglog(b.freq, np.abs(h), st, lw=1.1, label=lab)
        ax[1].semilogx(b.freq, np.degrees(np.angle(h)), st, lw=1.1)
    for a in ax:
        _marks(a, d.mismatches, b.recording)
    ax[0].set_ylabel("magnitude")
    ax[1].set_ylabel("phase [deg]")
    ax[1].set_xlabel("frequency [Hz]")
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"{b.recording} ({b.kind})")
    return save(fig, path)


def _points(b: PointsBlock, d, path: Path, nominal: PointsBlock | None) -> Path:
    from ..viz._common import figure, save

    before = (nominal or b).nuisance_fit(Model())
    after = b.nuisance_fit(d.model)
    if b.kind == "surface" and b.grid is not None:
        shape, flat = b.grid
        fig, ax = figure(1, 2, figsize=(11, 4.5))
        keep_nom = (nominal or b).keep
        for a, vals, keep, lab in (
            (ax[0], before, keep_nom, "before"),
            (ax[1], after, b.keep, "after"),
        ):
            img = np.full(shape[0] * shape[1], np.nan)
            img[flat[keep]] = vals * 1e9
            lim = np.nanpercentile(np.abs(img), 99) or 1.0
            im = a.imshow(
                img.reshape(shape), cmap="RdBu_r", vmin=-lim, vmax=lim, origin="upper"
            )
            a.set_title(f"{b.recording}: residual {lab} [nm]")
            fig.colorbar(im, ax=a, shrink=0.8)
        return save(fig, path)
    fig, ax = figure(figsize=(9, 3.5))
    s_nom = nominal or b
    for vals, blk, lab, c in (
        (before, s_nom, "before", "C0"),
        (after, b, "after", "C3"),
    ):
        pos = blk.along[blk.keep] if blk.along is not None else np.arange(vals.size)
        ax.plot(pos * 1e3, vals * 1e9, ".", ms=1, color=c, label=lab)
    ax.set_xlabel("position along the profile [mm]")
    ax.set_ylabel("residual [nm]")
    ax.legend(fontsize=8, markerscale=6)
    ax.set_title(f"{b.recording}: measured minus model")
    return save(fig, path)


def figures(d, out: Path) -> dict[str, Path]:
    """Write the before/after pictures of a :class:`Diagnosis` into ``out``.

    Returns
    -------
    dict of str to Path
        Picture name -> PNG file.
    """
    out = Path(out)
    res: dict[str, Path] = {}
    nominal = {id(b): n for b, n in zip(d.blocks, d.blocks_nominal, strict=True)}
    forces = {b.cut.recording: b for b in d.blocks if isinstance(b, ForceBlock)}
    for b in d.blocks:
        name = _safe(b.recording)
        if isinstance(b, SpectralBlock):
            res[f"{name}_spectrum"] = _spectrum(b, d, out / f"{name}_spectrum.png")
        elif isinstance(b, TimeBlock):
            res[f"{name}_residual"] = _timeseries(
                b, d, forces.get(b.recording), out / f"{name}_residual.png"
            )
        elif isinstance(b, FRFBlock):
            res[f"{name}_frf"] = _frf(b, d, out / f"{name}_frf.png")
        elif isinstance(b, PointsBlock):
            key = f"{name}_{'map' if b.kind == 'surface' else 'profile'}"
            n = nominal.get(id(b))
            res[key] = _points(b, d, out / f"{key}.png", n)
    return res


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
