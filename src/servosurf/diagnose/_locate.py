"""Locators: where a residual departs from the noise model, and how surely.

Every test has a stated null distribution under the block's noise model and a
family-wise false-alarm rate ``ALPHA`` per family of tests (Bonferroni over the
bands, bins, harmonics, windows or parts of a family):

* averaged periodograms of idle records: ``2 R P/S ~ chi2(2R)`` per bin (lines),
  summed over third-octave bands (broadband excess or deficit);
* whitened deterministic residuals: ``|rho_k|^2 ~ chi2(2)`` per bin, at the
  harmonics of the command (FTS) frequency, in third-octave bands, in time
  windows and folded on the command cycle;
* FRF log-ratio residuals: magnitude and phase separately per third-octave band;
* maps and profiles: along the cut (the tool's time history), across the cut
  (contact angle), the uncut top, and per integer spindle order.

The same tests on the residual after the fit decide whether anything is left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy as sp
import scipy.ndimage  # noqa: F401  (sp.ndimage)

from ._blocks import (
    CutBlock,
    ForceBlock,
    FRFBlock,
    PointsBlock,
    SpectralBlock,
    TimeBlock,
)
from .effects._base import Evidence, Model, Nominal

__all__ = [
    "Mismatch",
    "ALPHA",
    "locate",
    "gather",
    "third_octaves",
    "tag_frequency",
    "force_excess_logsf",
]

#: Family-wise false-alarm rate of each family of tests.
ALPHA = 1e-4
#: Largest reported significance (-log10 p); beyond it p is "zero".
MAX_SIGNIFICANCE = 1000.0


@dataclass
class Mismatch:
    """A located departure from the noise model.

    Attributes
    ----------
    recording : str
        Recording name.
    domain : str
        ``spectrum``, ``time``, ``frf``, ``force``, ``map`` or ``profile``.
    where : str
        Human-readable location (band, line, harmonic, time, part of the map).
    significance : float
        ``-log10`` of the Bonferroni-corrected p-value (>= 4 is reported).
    test : str
        The test (family) that found it.
    details : dict
        Numbers behind ``where`` (frequency in Hz, times in s, ratio...).
    """

    recording: str
    domain: str
    where: str
    significance: float
    test: str = ""
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {
            "recording": self.recording,
            "domain": self.domain,
            "where": self.where,
            "significance": round(float(self.significance), 2),
            "test": self.test,
            **({"details": self.details} if self.details else {}),
        }


def _chi2_logsf(x, dof):
    """log10 of the upper tail of chi2(dof) at x, finite in the far tail.

    Where scipy's ``logsf`` underflows, the Wilson-Hilferty normal approximation
    gives the order of magnitude.
    """
    x = np.asarray(x, dtype=float)
    v = np.asarray(sp.stats.chi2.logsf(x, dof), dtype=float)
    bad = ~np.isfinite(v)
    if np.any(bad):
        k = np.broadcast_to(np.asarray(dof, dtype=float), x.shape)[bad]
        z = ((x[bad] / k) ** (1 / 3) - (1 - 2 / (9 * k))) / np.sqrt(2 / (9 * k))
        v[bad] = sp.stats.norm.logsf(z)
    out = np.maximum(v / math.log(10.0), -MAX_SIGNIFICANCE)
    return float(out) if out.ndim == 0 else out


def _chi2_logcdf(x, dof):
    """log10 of the lower tail of chi2(dof) at x (a deficit), finite."""
    x = np.asarray(x, dtype=float)
    v = np.asarray(sp.stats.chi2.logcdf(x, dof), dtype=float)
    bad = ~np.isfinite(v)
    if np.any(bad):
        k = np.broadcast_to(np.asarray(dof, dtype=float), x.shape)[bad]
        z = ((np.maximum(x[bad], 0.0) / k) ** (1 / 3) - (1 - 2 / (9 * k))) / np.sqrt(
            2 / (9 * k)
        )
        v[bad] = sp.stats.norm.logcdf(z)
    out = np.maximum(v / math.log(10.0), -MAX_SIGNIFICANCE)
    return float(out) if out.ndim == 0 else out


def third_octaves(fmin: float, fmax: float) -> np.ndarray:
    """Edges (Hz) of third-octave bands covering [fmin, fmax]."""
    k0 = math.floor(3 * math.log2(max(fmin, 1e-3) / 1000.0))
    k1 = math.ceil(3 * math.log2(fmax / 1000.0))
    return 1000.0 * 2.0 ** (np.arange(k0, k1 + 2) / 3.0)


def tag_frequency(f: float, tol: float, refs: dict[str, float]) -> str:
    """Name ``f`` as a harmonic of a reference (``3 x FTS``) or ``other``."""
    tags = []
    for name, f0 in refs.items():
        if f0 <= 0:
            continue
        k = round(f / f0)
        if k >= 1 and abs(f - k * f0) <= tol and k <= 200:
            tags.append(f"{k} x {name}")
    return ", ".join(tags) if tags else "other"


def _bands(freq, stat, dof, n_tests, rec, domain, test, label, lower=False):
    out = []
    for f_lo, f_hi, s, d in zip(freq[:-1], freq[1:], stat, dof, strict=True):
        if d <= 0:
            continue
        lp = _chi2_logsf(s, d) + math.log10(n_tests)
        if lp < math.log10(ALPHA):
            ratio = s / d
            out.append(
                Mismatch(
                    rec,
                    domain,
                    f"{label} {f_lo:.0f}-{f_hi:.0f} Hz: "
                    f"power x{ratio:.3g} of the model",
                    -lp,
                    test,
                    {"band_hz": [float(f_lo), float(f_hi)], "ratio": float(ratio)},
                )
            )
        if lower:
            lc = _chi2_logcdf(s, d) + math.log10(n_tests)
            if lc < math.log10(ALPHA):
                out.append(
                    Mismatch(
                        rec,
                        domain,
                        f"{label} {f_lo:.0f}-{f_hi:.0f} Hz: "
                        f"power x{s / d:.3g} of the model (deficit)",
                        -lc,
                        test,
                        {"band_hz": [float(f_lo), float(f_hi)], "ratio": float(s / d)},
                    )
                )
    return out


def _spectral(b: SpectralBlock, p: Model, refs: dict) -> list[Mismatch]:
    s = b.expected(p)
    u = b.pbar / s
    R = b.nrec
    out = []
    edges = third_octaves(b.freq[0], b.freq[-1] * 1.0001)
    idx = np.digitize(b.freq, edges) - 1
    nb = edges.size - 1
    stat = np.bincount(idx, weights=2 * R * u, minlength=nb)[:nb]
    dof = 2 * R * np.bincount(idx, minlength=nb)[:nb]
    nt = int((dof > 0).sum())
    out += _bands(
        edges, stat, dof, nt, b.recording, "spectrum", "band-power", "band", lower=True
    )
    # lines: per-bin chi2(2R)
    lp = _chi2_logsf(2 * R * u, 2 * R) + math.log10(u.size)
    sig = np.nonzero(lp < math.log10(ALPHA))[0]
    df = b.fs / b.nsamp
    for k in _peaks(sig, u)[:12]:
        f = float(b.freq[k])
        out.append(
            Mismatch(
                b.recording,
                "spectrum",
                f"line at {f:.1f} Hz ({tag_frequency(f, df, refs)}): power x{u[k]:.3g}",
                -float(lp[k]),
                "line",
                {"frequency_hz": f, "ratio": float(u[k])},
            )
        )
    return out


def _peaks(sig: np.ndarray, val: np.ndarray) -> list[int]:
    """Local maxima of ``val`` at the significant indices ``sig``, strongest first.

    Every local maximum counts (a strong line's leakage can make one long run of
    significant bins that hides weaker lines inside it).
    """
    if sig.size == 0:
        return []
    v = np.asarray(val)
    left = np.concatenate([[-np.inf], v[:-1]])
    right = np.concatenate([v[1:], [-np.inf]])
    loc = sig[(v[sig] > left[sig]) & (v[sig] >= right[sig])]
    return [int(k) for k in loc[np.argsort(-v[loc])]]


def _fundamental(x: np.ndarray, fs: float, hint: float = 0.0) -> float:
    """Fundamental frequency (Hz) of a command: the hint (FTS frequency) when the
    spectral peak is within two bins of it, else the interpolated peak."""
    if x is None or not np.any(x):
        return 0.0
    X = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(x.size)))
    k = int(np.argmax(X[1:])) + 1
    df = fs / x.size
    if hint > 0 and abs(k * df - hint) <= 2 * df:
        return hint
    if 1 <= k < X.size - 1:
        a, b, c = np.log(X[k - 1] + 1e-300), np.log(X[k]), np.log(X[k + 1] + 1e-300)
        den = a - 2 * b + c
        k = k + (0.5 * (a - c) / den if den != 0 else 0.0)
    return k * df


def _timeblock(b: TimeBlock, p: Model, refs: dict, f0: float) -> list[Mismatch]:
    out = []
    dom = "time"
    for i, (keep, w, f) in enumerate(b.meta):
        x = b.whitened(p, i)
        e = x.real**2 + x.imag**2
        if not np.all(np.isfinite(e)):
            out.append(
                Mismatch(b.recording, dom, "simulation diverged", 300.0, "global")
            )
            continue
        edges = third_octaves(f[0], f[-1] * 1.0001)
        idx = np.digitize(f, edges) - 1
        nb = edges.size - 1
        stat = np.bincount(idx, weights=e, minlength=nb)[:nb]
        dof = 2 * np.bincount(idx, minlength=nb)[:nb]
        out += _bands(
            edges,
            stat,
            dof,
            int((dof > 0).sum()),
            b.recording,
            dom,
            "band-power",
            f"record {i + 1}, band" if len(b.meta) > 1 else "band",
        )
        df = b.fs / b.records[i]["fe"].size
        if f0 > 0:
            ks = np.arange(1, int(min(f[-1], 40 * f0) / f0) + 1)
            for k in ks:
                j = int(np.argmin(np.abs(f - k * f0)))
                if abs(f[j] - k * f0) > df:
                    continue
                lp = _chi2_logsf(e[j], 2) + math.log10(ks.size)
                if lp < math.log10(ALPHA):
                    out.append(
                        Mismatch(
                            b.recording,
                            dom,
                            f"harmonic {k} of the {f0:.4g} Hz command ({f[j]:.1f} Hz)",
                            -lp,
                            "harmonic",
                            {"frequency_hz": float(f[j]), "harmonic": int(k)},
                        )
                    )
        lp = _chi2_logsf(e, 2) + math.log10(e.size)
        sig = np.nonzero(lp < math.log10(ALPHA))[0]
        for k in _peaks(sig, e)[:8]:
            fk = float(f[k])
            if f0 > 0 and abs(fk / f0 - round(fk / f0)) * f0 <= df:
                continue
            out.append(
                Mismatch(
                    b.recording,
                    dom,
                    f"line at {fk:.1f} Hz ({tag_frequency(fk, df, refs)})",
                    -float(lp[k]),
                    "line",
                    {"frequency_hz": fk},
                )
            )
        # time windows of the whitened residual
        wt = b.whitened_time(p, i)
        n = wt.size
        nw = max(int(round(2e-3 * b.fs)), 32)
        m = n // nw
        if m >= 2:
            en = (wt[: m * nw] ** 2).reshape(m, nw).sum(axis=1)
            lp = _chi2_logsf(en, nw) + math.log10(m)
            j = int(np.argmin(lp))
            if lp[j] < math.log10(ALPHA):
                t0 = b.records[i].get("t0", 0.0) + j * nw / b.fs
                frac = float((lp < math.log10(ALPHA)).mean())
                out.append(
                    Mismatch(
                        b.recording,
                        dom,
                        f"time {1e3 * t0:.2f}-"
                        f"{1e3 * (t0 + nw / b.fs):.2f} ms (strongest of "
                        f"{100 * frac:.0f} % flagged windows)",
                        -float(lp[j]),
                        "time-window",
                        {"t_s": [t0, t0 + nw / b.fs], "flagged_fraction": frac},
                    )
                )
        if f0 > 0:
            per = b.fs / f0
            ncyc = int(n // per)
            if ncyc >= 3:
                nph = 20
                ph = np.floor((np.arange(int(ncyc * per)) % per) / per * nph).astype(
                    int
                )
                sums = np.bincount(ph, weights=wt[: ph.size], minlength=nph)
                cnt = np.bincount(ph, minlength=nph)
                z2 = sums**2 / np.maximum(cnt, 1)
                lp = _chi2_logsf(z2, 1) + math.log10(nph)
                j = int(np.argmin(lp))
                if lp[j] < math.log10(ALPHA):
                    out.append(
                        Mismatch(
                            b.recording,
                            dom,
                            f"locked to the command "
                            f"cycle at phase {j / nph:.2f}-"
                            f"{(j + 1) / nph:.2f} ({1e3 * j / nph / f0:.2f} "
                            "ms after the cycle start)",
                            -float(lp[j]),
                            "cycle-phase",
                            {"phase": [j / nph, (j + 1) / nph]},
                        )
                    )
    return out


#: Efficiency of the force-noise estimate (MAD of first differences) relative to a
#: known sigma: the variance of log(sum r^2 / n) is (2 / n) (1 + 1 / EFF). Measured
#: on white noise (tests/diagnose: 0.77 at n = 32768).
MAD_DIFF_EFFICIENCY = 0.77


def variance_excess_logsf(
    ss: float, dof: int, *, share: float, sigma_dof: float, overlap: int
) -> float | None:
    """log10 p of a whitened sum of squares this large, with sigma estimated.

    The map and profile residuals are divided by an instrument sigma estimated
    from the data (:class:`PointsBlock`, ``sigma_dof`` dof). To first order the
    statistic's mean square is ``1 - share * e`` with ``e`` the relative error of
    the variance estimate (variance ``2 / sigma_dof``), and ``overlap`` of its
    ``dof`` values were themselves part of that estimate, so

        var(ss / dof) = 2 / dof + 2 share^2 / sigma_dof
                        - 4 share overlap / (dof sigma_dof),

    matched by a scaled chi2 with ``k = 2 / var`` dof (an F test when ``share``
    is 1 and nothing overlaps). Treating sigma as known made a chi2(dof) test
    fire on null cases (measured: the along-cut RMS ratio of null ring profiles
    spread 1.3x wider than chi2 and followed the uncut top's).

    Parameters
    ----------
    ss : float
        Sum of squares of the whitened values, dimensionless.
    dof : int
        Their degrees of freedom.
    share : float
        Share (0-1) of their variance that is the estimated instrument noise.
    sigma_dof : float
        dof of the instrument-variance estimate (``inf`` when known).
    overlap : int
        How many of the ``dof`` entered that estimate.

    Returns
    -------
    float or None
        log10 of the one-sided p-value; None when the statistic is fixed by the
        estimate itself (it then carries no information, e.g. the uncut top of a
        profile whose noise is estimated from it alone).
    """
    if dof < 1:
        return None
    var = 2.0 / dof
    if math.isfinite(sigma_dof) and sigma_dof > 0:
        var += 2.0 * share**2 / sigma_dof - 4.0 * share * overlap / (dof * sigma_dof)
    if var < 0.05 * 2.0 / dof:
        return None
    k = 2.0 / var
    return _chi2_logsf(ss / dof * k, k)


def force_excess_logsf(r: np.ndarray, var_log_sigma: float | None = None) -> float:
    """log10 p of the residual power excess of a force record (one-sided).

    Parameters
    ----------
    r : ndarray of shape (n,)
        Force residual divided by the noise sigma estimated from the same record
        (:class:`ForceBlock`), dimensionless.
    var_log_sigma : float, optional
        Variance of the log of the estimated noise variance when it is the
        periodogram median of a subset of the compared bins
        (:func:`servosurf.diagnose._blocks.white_level`, ``ForceBlock``); without
        it the sigma is the MAD of first differences of the n samples.

    Returns
    -------
    float
        log10 of the probability, under white noise of the estimated sigma, of a
        mean square at least this large. The sigma is estimated, not known, so the
        statistic is log(mean square) ~ N(0, var_log_sigma - 2 / n) (median of
        a subset of the bins) or N(0, (2 / n) (1 + 1 / MAD_DIFF_EFFICIENCY)) (MAD
        of differences), not chi2(n) / n.
    """
    n = r.size
    if n < 2:
        return 0.0
    ms = float(r @ r) / n
    if not ms > 0:
        return 0.0
    if var_log_sigma is None:
        sd = math.sqrt(2.0 / n + 2.0 / (n * MAD_DIFF_EFFICIENCY))
    else:
        # the level is the median of a subset of the same periodogram bins: the
        # mean square and the median co-vary, cov(log mean, log median) = 1/N for
        # N exponential bins (the median's influence sign(x - ln 2) against x - 1)
        sd = math.sqrt(max(var_log_sigma - 2.0 / n, 0.25 * var_log_sigma))
    return float(sp.stats.norm.logsf(math.log(ms) / sd) / math.log(10.0))


def _force(b: ForceBlock, p: Model) -> list[Mismatch]:
    r = b.residual(p)
    n = r.size
    lp = force_excess_logsf(r, b.var_log_sigma)
    if lp < math.log10(ALPHA):
        F = b.transform(b.cut.predict(p)["force"])
        c = float(np.dot(r, F) / max(np.linalg.norm(F) * np.linalg.norm(r), 1e-300))
        return [
            Mismatch(
                b.recording,
                "force",
                f"measured force differs from the chip "
                f"model (RMS x{math.sqrt(r @ r / n):.3g} of the noise; "
                f"correlation with the modelled force {c:+.2f})",
                -lp,
                "global",
                {"correlation": c},
            )
        ]
    return []


def _frf(b: FRFBlock, p: Model) -> list[Mismatch]:
    r = b.residual(p)
    m = b.freq.size
    re, im = r[:m], r[m:] if r.size >= 2 * m else r[m:]
    if re.size != m or im.size != m:  # gain nuisance removes no entries here
        re, im = r[:m], r[-m:]
    edges = third_octaves(b.freq[0], b.freq[-1] * 1.0001)
    idx = np.digitize(b.freq, edges) - 1
    nb = edges.size - 1
    out = []
    for part, v in (("magnitude", re), ("phase", im)):
        stat = np.bincount(idx, weights=v**2, minlength=nb)[:nb]
        dof = np.bincount(idx, minlength=nb)[:nb].astype(float)
        nt = 2 * int((dof > 0).sum())
        for f_lo, f_hi, s, d in zip(edges[:-1], edges[1:], stat, dof, strict=True):
            if d <= 0:
                continue
            lp = _chi2_logsf(s, d) + math.log10(nt)
            if lp < math.log10(ALPHA):
                sel = (b.freq >= f_lo) & (b.freq < f_hi)
                k = np.argmax(np.abs(v[sel]))
                fk = float(b.freq[sel][k])
                val = float(v[sel][k] * b.sigma)
                txt = (
                    f"{100 * (math.exp(val) - 1):+.2g} %"
                    if part == "magnitude"
                    else f"{math.degrees(val):+.2g} deg"
                )
                out.append(
                    Mismatch(
                        b.recording,
                        "frf",
                        f"{part} {f_lo:.0f}-{f_hi:.0f} "
                        f"Hz (largest {txt} at {fk:.0f} Hz)",
                        -lp,
                        f"frf-{part}",
                        {"band_hz": [float(f_lo), float(f_hi)], "frequency_hz": fk},
                    )
                )
    return out


def _points(b: PointsBlock, p: Model) -> tuple[list[Mismatch], list[int]]:
    """Mismatches of a map or profile and its most significant spindle orders."""
    w = b.residual(p)
    orders: list[int] = []
    out = []
    dom = b.domain
    n_unc = int((~b.cut).sum())
    n_cut = int(b.cut.sum())
    # (label, whitened values, share of their variance that is instrument noise,
    # how many of their dof went into the instrument-noise estimate)
    parts = []
    if n_unc:
        parts.append(
            (
                "uncut top (instrument noise, piston, tilt)",
                w[:n_unc],
                1.0,
                b.sigma_parts["uncut"],
            )
        )
    if n_cut:
        parts.append(
            (
                "across the cut (contact angle: tool shape, recovery)",
                w[n_unc : n_unc + n_cut],
                1.0,
                b.sigma_parts["within"],
            )
        )
        parts.append(
            (
                "along the cut (tool height in time: servo, sensor, drift, spindle)",
                w[n_unc + n_cut :],
                b.instrument_share,
                0,
            )
        )
    for label, v, share, overlap in parts:
        if v.size == 0:
            continue
        if label.startswith("along") and b.ml_rho2 > 0.5:
            # the instrument sigma was fitted to these statistics themselves
            # (maximum likelihood): their sum of squares is fixed by it
            continue
        dof = v.size if "across" not in label else max(b.n_within, 1)
        lp = variance_excess_logsf(
            float(v @ v), dof, share=share, sigma_dof=b.sigma_dof, overlap=overlap
        )
        if lp is None:
            continue
        lp += math.log10(len(parts))
        if lp < math.log10(ALPHA):
            out.append(
                Mismatch(
                    b.recording,
                    dom,
                    f"{label}: RMS x{math.sqrt(float(v @ v) / dof):.3g} of the noise",
                    -lp,
                    "part",
                    {},
                )
            )
    # patterns repeating in every lenslet (folded on the FTS period) and a drift
    # across the array (trend in cutting time): GLS tests of indicator templates
    fts = (
        getattr(b.ctx.case.toolpath.path, "frequency", 0.0)
        if b.ctx.case.toolpath.kind == "lenslet"
        else 0.0
    )
    if n_cut and b.segments and len(b.segments) >= 4:
        tc = b.tpass[b.cut]
        tests = []
        if fts > 0:
            nph = 16
            ph = np.floor(np.mod(tc * fts, 1.0) * nph).astype(int)
            cols = np.zeros((b.z.size, nph))
            cols[np.nonzero(b.cut)[0], ph] = 1.0
            tests.append(
                (
                    "repeating in every lenslet (same lenslet phase)",
                    cols,
                    "lenslet-phase",
                    nph,
                )
            )
        cols = np.zeros((b.z.size, 1))
        cols[b.cut, 0] = (tc - tc.mean()) / max(np.ptp(tc), 1e-9)
        tests.append(
            ("drifting across the array (trend in cutting time)", cols, "trend", 1)
        )
        for label, cols, test, dof in tests:
            wc = b._whiten(cols)
            wc = wc - b.q @ (b.q.T @ wc)
            c, *_ = np.linalg.lstsq(wc, w, rcond=None)
            lam = float(np.sum((wc @ c) ** 2))
            lp = _chi2_logsf(lam, dof) + math.log10(2)
            if lp < math.log10(ALPHA):
                out.append(
                    Mismatch(
                        b.recording,
                        dom,
                        label,
                        -lp,
                        test,
                        {"statistic": lam, "dof": dof},
                    )
                )
    # lines in the tool height: periodogram of the along-cut residual on a regular
    # time grid (gaps zero-filled), peaks against the local median, then an exact
    # GLS test of the few strongest
    if n_cut and b.nb > 64:
        r = b.nuisance_fit(p)[b.cut]
        bins = b.bins[b.cut]
        mb = np.bincount(bins, weights=r, minlength=b.nb) / np.maximum(b.counts, 1)
        tb = b.tb
        span = float(tb.max() - tb.min())
        if span > 0.05:
            dt = max(float(np.median(np.diff(np.sort(tb)))), 1.0 / b.ctx.case.fs)
            m = int(span / dt) + 1
            if m <= 1 << 21:
                g = np.zeros(m)
                g[np.clip(((tb - tb.min()) / dt).astype(int), 0, m - 1)] = mb
                P = np.abs(np.fft.rfft(g)) ** 2
                fr = np.fft.rfftfreq(m, dt)
                sel = (fr > 20.0) & (fr < 0.45 / dt)
                if sel.sum() > 64:
                    Ps = P[sel]
                    k = 101
                    med = sp.ndimage.median_filter(Ps, size=k, mode="nearest")
                    ratio = Ps / np.maximum(med, 1e-300)
                    cand = np.nonzero(ratio > 25.0)[0]
                    fs_ = fr[sel]
                    for j in _peaks(cand, ratio)[:4]:
                        f0 = float(fs_[j])
                        cols = np.zeros((b.z.size, 2))
                        cols[b.cut, 0] = np.cos(2 * np.pi * f0 * b.tpass[b.cut])
                        cols[b.cut, 1] = np.sin(2 * np.pi * f0 * b.tpass[b.cut])
                        wc = b._whiten(cols)
                        wc = wc - b.q @ (b.q.T @ wc)
                        c, *_ = np.linalg.lstsq(wc, w, rcond=None)
                        lam = float(np.sum((wc @ c) ** 2))
                        lp = _chi2_logsf(lam, 2) + math.log10(max(sel.sum(), 1))
                        if lp < math.log10(ALPHA):
                            out.append(
                                Mismatch(
                                    b.recording,
                                    dom,
                                    f"line at {f0:.2f} Hz "
                                    "in the tool height (fixed frequency, "
                                    "not locked to the spindle)",
                                    -lp,
                                    "line",
                                    {"frequency_hz": f0},
                                )
                            )
    # integer spindle orders: GLS test of cos/sin(h theta) templates (chi2(2))
    if n_cut:
        th = b.pts.theta
        span = float(np.ptp(np.unwrap(np.sort(th[b.cut]))))
        hmax = 40
        if span > 0.5:
            cols = np.zeros((th.size, 2 * hmax))
            for h in range(1, hmax + 1):
                cols[b.cut, 2 * h - 2] = np.cos(h * th[b.cut])
                cols[b.cut, 2 * h - 1] = np.sin(h * th[b.cut])
            wc = b._whiten(cols)
            wc = wc - b.q @ (b.q.T @ wc)
            lam = np.zeros(hmax)
            amp = np.zeros(hmax)
            for h in range(hmax):
                t2 = wc[:, 2 * h : 2 * h + 2]
                c, *_ = np.linalg.lstsq(t2, w, rcond=None)
                lam[h] = float(np.sum((t2 @ c) ** 2))
                amp[h] = math.hypot(c[0], c[1])
            lp = _chi2_logsf(lam, 2) + math.log10(hmax)
            for h in np.argsort(lp)[:4]:
                sig = bool(lp[h] < math.log10(ALPHA))
                if sig:
                    out.append(
                        Mismatch(
                            b.recording,
                            dom,
                            f"spindle order {h + 1} (amplitude {amp[h] * 1e9:.3g} nm)",
                            -float(lp[h]),
                            "spindle-order",
                            {"order": int(h + 1), "amplitude_m": float(amp[h])},
                        )
                    )
            orders = [int(k + 1) for k in np.argsort(lp)[:4]]
    return out, orders


def _locate(blocks, p: Model, refs: dict[str, float]):
    """Mismatches (sorted by decreasing significance) and the spindle-order
    candidates of the maps and profiles (in block order)."""
    out: list[Mismatch] = []
    orders: list[int] = []
    for b in blocks:
        if isinstance(b, SpectralBlock):
            out += _spectral(b, p, refs)
        elif isinstance(b, CutBlock):
            out += _timeblock(b, p, refs, refs.get("FTS", 0.0))
        elif isinstance(b, TimeBlock):
            cmd = b.records[0].get("command")
            out += _timeblock(b, p, refs, _fundamental(cmd, b.fs, refs.get("FTS", 0.0)))
        elif isinstance(b, ForceBlock):
            out += _force(b, p)
        elif isinstance(b, FRFBlock):
            out += _frf(b, p)
        elif isinstance(b, PointsBlock):
            mm, ords = _points(b, p)
            out += mm
            orders += ords
    out.sort(key=lambda m: -m.significance)
    return out, orders


def locate(blocks, p: Model, refs: dict[str, float]) -> list[Mismatch]:
    """Run every locator on every block's residual under ``p``.

    Parameters
    ----------
    blocks : list of Block
        The likelihood blocks.
    p : Model
        Model whose residual is examined (nominal: "where is the mismatch";
        fitted: "what is left").
    refs : dict of str to float
        Reference frequencies (Hz) for harmonic tags: spindle, FTS, mains.

    Returns
    -------
    list of Mismatch
        Sorted by decreasing significance.
    """
    return _locate(blocks, p, refs)[0]


def gather(case, blocks, p: Model, refs: dict[str, float], *,
           recording_kinds=None, previous: Evidence | None = None):
    """Locate the mismatch of ``p`` and gather the evidence the effects place their
    configurations by.

    Parameters
    ----------
    case : CaseModel
        The case.
    blocks : list of Block
        The likelihood blocks.
    p : Model
        Model whose residual is located.
    refs : dict of str to float
        Reference frequencies (Hz) for harmonic tags.
    recording_kinds : mapping of str to str, optional
        Recording name -> kind (from the manifest).
    previous : Evidence, optional
        The evidence located on the nominal model, when ``p`` is a fitted one.

    Returns
    -------
    mismatches : list of Mismatch
        As :func:`locate`.
    evidence : Evidence
        The case's facts, the mismatches, the nominal model's FRF residual peaks
        and current demand, and the maps' spindle-order candidates.
    """
    from ..noise import evaluate_psd

    mism, orders = _locate(blocks, p, refs)
    m = case.machine
    spec = case.toolpath
    p0 = Model()
    strokes = []
    currents = []
    rec_len = 4096
    # the current limit acts on the DAC command itself (ServoLoop's amplifier)
    for b in blocks:
        if isinstance(b, TimeBlock):
            for i, rec in enumerate(b.records):
                if "command" in rec:
                    strokes.append(float(np.max(np.abs(rec["command"]))))
                u = b.predict(p0, i)["u"]
                currents.append(np.abs(u) * m.actuator.current_gain)
        if isinstance(b, SpectralBlock):
            # in controller samples: fs / record_length is the idle bin width
            rec_len = b.nsamp * case.fs / b.fs
    if spec is not None:
        t = np.linspace(0, 0.05, 2000)
        strokes.append(float(np.max(np.abs(spec.path.z_at(t)))))
    stroke = max(strokes) if strokes and max(strokes) > 1e-9 else 10e-6
    # FRF residual peaks of the nominal model
    peaks = []
    for b in blocks:
        if isinstance(b, FRFBlock):
            r = b.residual(p0)
            k = b.freq.size
            mag = np.abs(r[:k]) + np.abs(r[k : 2 * k])
            if mag.size > 5:
                sm = np.convolve(mag, np.ones(3) / 3, mode="same")
                j = int(np.argmax(sm))
                if sm[j] > 4:
                    peaks.append(float(b.freq[j]))
    sn = m.disturbances.sensor_noise
    nominal = Nominal(
        moving_mass=m.mechanics.moving_mass,
        flexure_stiffness=m.mechanics.k2,
        flexure_damping=max(m.mechanics.c2, 1e-3),
        force_constant=m.actuator.force_constant,
        sensor_bandwidth=m.sensor.bandwidth,
        delay=m.controller.delay,
        sensor_floor=sn.floor,
        sensor_corner=sn.corner,
        sensor_level=float(math.sqrt(evaluate_psd(sn, np.array([1000.0]))[0])),
        specific_force=case.specific_force,
        max_current=m.actuator.max_current,
        tool_radius=case.tool_radius(),
    )
    ev = Evidence(
        fs=case.fs,
        fts=float(spec.path.frequency)
        if spec is not None and spec.kind == "lenslet" else 0.0,
        stroke=stroke,
        record_length=rec_len,
        mismatches=tuple(mism),
        frf_peaks=tuple(peaks),
        order_candidates=tuple(orders),
        current_demand=np.concatenate(currents) if currents else np.zeros(0),
        kinds=frozenset(b.kind for b in blocks),
        recording_kinds=dict(recording_kinds or {}),
        nominal=nominal,
        case=case,
        previous=previous,
    )
    return mism, ev
