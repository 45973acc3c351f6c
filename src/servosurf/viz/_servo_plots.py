"""Figures of the positioning-error study (seed paper Figs 9, 10, 13, 15)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import figure, save

__all__ = [
    "plot_disturbance_frfs",
    "plot_cas",
    "plot_rms_vs_bandwidth",
    "plot_error_spectra",
    "plot_power_shares",
    "plot_loop_bode",
    "plot_tool_frfs",
]

_SRC_LABEL = {
    "sensor_noise": "sensor noise Ws",
    "current_noise": "current noise Wi",
    "base_vibration": "base vibration Wg",
    "base": "base vibration",
    "force": "cutting force",
    "reference": "reference",
}


def plot_loop_bode(frfs: dict, path: str | Path, margins: dict | None = None) -> Path:
    """Bode plot of the open loop L per mass, with |S| and |T| and the margins.

    Parameters
    ----------
    frfs : dict
        Label (e.g. "0.175 kg") -> :class:`~servosurf.servo.LoopFRF` (its ``loop``
        is the open-loop gain L, dimensionless).
    path : str or Path
        Output PNG.
    margins : dict, optional
        Label -> :meth:`ServoLoop.margins` dict; the crossover frequency (Hz) and
        phase margin (degree) are marked and named.

    Returns
    -------
    Path
        The PNG written.
    """
    fig, ax = figure(2, 1, figsize=(8, 7), sharex=True)
    for k, (label, fr) in enumerate(frfs.items()):
        c = f"C{k}"
        mag_db = 20 * np.log10(np.abs(fr.loop))
        phase = np.degrees(np.unwrap(np.angle(fr.loop)))
        phase -= 360.0 * np.round(phase[0] / 360.0)  # start within +-180 degrees
        ax[0].semilogx(fr.freq, mag_db, color=c, label=f"|L| open loop ({label})")
        ax[0].semilogx(fr.freq, 20 * np.log10(np.abs(fr.sensitivity)), ":", color=c,
                       lw=1, label=f"|S| = |1/(1+L)| ({label})")
        ax[0].semilogx(fr.freq, 20 * np.log10(np.abs(fr.complementary)), "--",
                       color=c, lw=1, label=f"|T| = |L/(1+L)| ({label})")
        ax[1].semilogx(fr.freq, phase, color=c, label=f"phase of L ({label})")
        m = (margins or {}).get(label) or {}
        fc, pm = m.get("crossover_hz"), m.get("phase_margin_deg")
        if fc is not None and np.isfinite(fc):
            for a in ax:
                a.axvline(fc, color=c, lw=0.7, alpha=0.6)
            ax[1].annotate(
                f"crossover {fc:.0f} Hz\nphase margin {pm:.1f} deg",
                (fc, -180.0 + (pm if np.isfinite(pm) else 0.0)),
                xytext=(8, -30 - 28 * k), textcoords="offset points", fontsize=7,
                color=c,
                arrowprops={"arrowstyle": "-", "color": c, "lw": 0.5},
            )
    ax[0].axhline(0.0, color="0.5", lw=0.5)
    ax[1].axhline(-180.0, color="0.5", lw=0.5)
    ax[0].set_ylabel("magnitude [dB]")
    ax[0].set_ylim(bottom=max(ax[0].get_ylim()[0], -80.0))
    ax[0].legend(fontsize=6, ncol=2)
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].set_ylabel("phase of L [deg]")
    ax[1].set_xlabel("frequency [Hz]")
    ax[1].grid(True, which="both", alpha=0.3)
    ax[0].set_title("Servo loop: open-loop gain L (controller x amplifier x mechanics "
                    "x sensor),\nsensitivity S and complementary sensitivity T",
                    fontsize=10)
    return save(fig, path)


def plot_tool_frfs(frfs: dict, path: str | Path) -> Path:
    """Closed-loop FRFs from every input to the tool position, per mass.

    ``frfs`` maps a label (e.g. "0.175 kg") to a :class:`~servosurf.servo.LoopFRF`;
    magnitudes in SI units per input unit (m/m, m/A, m/N), phases in degrees.
    """
    fig, ax = figure(2, 1, figsize=(8, 7), sharex=True)
    paths = [
        ("reference", "tool", "m/m"),
        ("sensor_noise", "tool", "m/m"),
        ("current_noise", "tool", "m/A"),
        ("base", "tool", "m/m"),
        ("force", "tool", "m/N"),
    ]
    styles = ["-", "--", ":", "-."]
    for k, (label, fr) in enumerate(frfs.items()):
        for j, (i, o, unit) in enumerate(paths):
            h = fr.paths[(i, o)]
            c = f"C{j}"
            ax[0].loglog(
                fr.freq,
                np.abs(h),
                styles[k % 4],
                color=c,
                label=f"{_SRC_LABEL.get(i, i)} [{unit}] ({label})",
            )
            ax[1].semilogx(fr.freq, np.degrees(np.angle(h)), styles[k % 4], color=c)
    ax[0].set_ylabel("|FRF| to tool position (SI units per input)")
    ax[0].legend(fontsize=6, ncol=2)
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].set_ylabel("phase [deg]")
    ax[1].set_xlabel("frequency [Hz]")
    ax[1].grid(True, which="both", alpha=0.3)
    ax[0].set_title("Closed loop: FRFs from the reference and each disturbance to "
                    "the tool position", fontsize=10)
    return save(fig, path)


def plot_disturbance_frfs(frfs: dict, path: str | Path) -> Path:
    """Magnitude of disturbance -> measured position FRFs per mass (Fig. 9a)."""
    fig, ax = figure(figsize=(8, 5))
    styles = ["-", "--", ":", "-."]
    for k, (label, fr) in enumerate(frfs.items()):
        for j, (i, unit) in enumerate(
            (("sensor_noise", "m/m"), ("current_noise", "m/A"), ("base", "m/m"))
        ):
            ax.loglog(
                fr.freq,
                np.abs(fr.paths[(i, "sensor")]),
                styles[k % 4],
                color=f"C{j}",
                label=f"{_SRC_LABEL[i]} [{unit}] ({label})",
            )
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("|FRF| to measured position")
    ax.set_title("Disturbance to sensor FRFs (cf. Fig. 9a)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return save(fig, path)


def plot_cas(budgets: dict, path: str | Path) -> Path:
    """CAS of the real error per source and in total, per mass (Fig. 9b)."""
    fig, ax = figure(figsize=(8, 5))
    styles = ["-", "--", ":", "-."]
    for k, (label, b) in enumerate(budgets.items()):
        for j, (name, c) in enumerate(b.cas_real().items()):
            ax.semilogx(
                b.freq,
                c * 1e9,
                styles[k % 4],
                color=f"C{j}",
                label=f"{_SRC_LABEL.get(name, name)} ({label})",
            )
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("CAS of real positioning error [nm]")
    ax.set_title("Cumulative amplitude spectrum (Eq. 11, cf. Fig. 9b)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return save(fig, path)


def plot_rms_vs_bandwidth(study, path: str | Path) -> Path:
    """RMS real and following error against crossover bandwidth per mass (Fig. 10)."""
    fig, ax = figure(1, 2, figsize=(11, 4.5))
    for i, m in enumerate(study.masses):
        c = f"C{i}"
        ax[0].plot(
            study.bandwidths,
            study.rms_real[i] * 1e9,
            "o-",
            color=c,
            ms=3,
            label=f"{m:g} kg",
        )
        ax[1].plot(
            study.bandwidths,
            study.rms_following[i] * 1e9,
            "o-",
            color=c,
            ms=3,
            label=f"{m:g} kg",
        )
        if np.isfinite(study.optimal_bandwidth[i]):
            ax[0].axvline(study.optimal_bandwidth[i], color=c, ls=":", lw=1)
            ax[0].annotate(
                f"opt {study.optimal_bandwidth[i]:.0f} Hz",
                (study.optimal_bandwidth[i], study.optimal_rms[i] * 1e9),
                fontsize=7,
                color=c,
            )
        if np.isfinite(study.stability_limit[i]):
            for a in ax:
                a.axvline(study.stability_limit[i], color=c, ls="--", lw=0.8)
    ax[0].set_title("RMS real positioning error (cf. Fig. 10a)")
    ax[1].set_title("RMS following error (cf. Fig. 10b)")
    for a in ax:
        a.set_xlabel("crossover bandwidth [Hz] (dashed: stability limit)")
        a.set_ylabel("RMS error [nm]")
        a.grid(True, alpha=0.3)
        a.legend()
    return save(fig, path)


def plot_error_spectra(budgets: dict, path: str | Path) -> Path:
    """Real and following error PSDs per configuration (Fig. 13)."""
    n = len(budgets)
    fig, ax = figure(n, 1, figsize=(8, 3.2 * n), squeeze=False)
    for k, (label, b) in enumerate(budgets.items()):
        a = ax[k, 0]
        a.loglog(b.freq, b.following_total, color="C3", label="following error PSD")
        a.loglog(b.freq, b.real_total, color="C2", label="real positioning error PSD")
        for pk in b.peaks():
            a.axvline(pk, color="C2", ls=":", lw=0.8)
            a.annotate(
                f"{pk / 1e3:.1f} kHz",
                (pk, np.interp(pk, b.freq, b.real_total)),
                fontsize=7,
                color="C2",
            )
        a.set_ylabel("PSD [m^2/Hz]")
        a.set_title(label)
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    ax[-1, 0].set_xlabel("frequency [Hz]")
    return save(fig, path)


def plot_power_shares(
    bandwidths, shares: dict, path: str | Path, *, title: str = ""
) -> Path:
    """Share of real-error power per source against bandwidth (Fig. 15)."""
    fig, ax = figure(figsize=(8, 4.5))
    bottom = np.zeros(len(bandwidths))
    x = np.arange(len(bandwidths))
    for j, (name, vals) in enumerate(shares.items()):
        v = np.asarray(vals) * 100
        ax.bar(x, v, bottom=bottom, color=f"C{j}", label=_SRC_LABEL.get(name, name))
        bottom += np.nan_to_num(v)
    ax.set_xticks(x, [f"{b:.0f}" for b in bandwidths], rotation=45)
    ax.set_xlabel("crossover bandwidth [Hz]")
    ax.set_ylabel("share of real-error power [%]")
    ax.set_title(title or "Error power contribution per source (cf. Fig. 15)")
    ax.legend(fontsize=8)
    return save(fig, path)
