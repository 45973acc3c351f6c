"""Likelihood blocks: one per recording channel, each a whitened residual.

Every block turns "measured minus simulated under a :class:`Model`" into a
vector whose sum of squares is the block's deviance (-2 log-likelihood up to a
data-only constant), with its nuisance parameters (gains, piston, tilt, lateral
registration) profiled out by projection. The model-selection code only ever sees
``residual(p)`` and ``n`` (real observations).

Noise models (fixed when a block is built; blocks are rebuilt after every accepted
term so that accepted lines, modes and noise shapes enter the weighting):

* following error: stationary Gaussian with the synthesised PSD (paper Eq 10);
  idle records use the Whittle likelihood of the averaged periodogram (deviance
  residuals, lines as power), commanded records the frequency-domain GLS of the
  deterministic residual (lines as sinusoids of free phase, projected out);
* FRF: complex log-ratio with a constant relative noise estimated from the data
  (robust second differences), floor 1e-3;
* cut force: white, level estimated from the data, floor 1e-4 of the peak force;
* maps and profiles: tool vibration (the synthesised real-error PSD) shared by
  all points cut at the same instant, plus white instrument noise estimated from
  the data (floor 0.05 nm); lines as sinusoids of the pass time, projected out.
"""

from __future__ import annotations

import functools as _functools
import math

import numpy as np
import scipy as sp
import scipy.sparse  # noqa: F401  (sp.sparse)

from ._sim import CaseModel
from .effects._base import Model

__all__ = [
    "Block",
    "SpectralBlock",
    "TimeBlock",
    "CutBlock",
    "ForceBlock",
    "FRFBlock",
    "PointsBlock",
    "Context",
    "line_power",
]

#: Residual returned when the simulated loop diverges (huge but finite).
_DIVERGED = 1e6
#: Relative FRF noise floor.
FRF_FLOOR = 1e-3
#: Instrument noise floor of maps and profiles, m.
MAP_FLOOR = 0.05e-9
#: Points closer than this to the uncut top are left out (cut edge), m.
EDGE_MARGIN = 30e-9
#: Cut points whose runner-up pass lies less than this many standard deviations
#: of the two passes' tool-noise difference above the active pass are left out.
AMBIGUITY_SIGMAS = 4.0
#: Fewer instrument-only values (within intervals and on the uncut top) than this
#: (or than half the interval statistics) and the instrument sigma is estimated by
#: maximum likelihood of the statistics too.
MIN_SIGMA_POINTS = 2000
#: Range of the tool-noise power scale profiled from a map (a factor 2 on a
#: disturbance PSD is a recalibration, not physics: DISCOVERY.md, issue 19).
TOOL_SCALE_BOUNDS = (0.5, 2.0)
#: Segments (revolutions) used by the maximum-likelihood estimates.
ML_SEGMENTS = 24
#: Points closer than this to the cut boundary (in the plane) are left out, m.
EDGE_BAND = 2e-6
#: Registration of a map or profile (:meth:`PointsBlock._register`): at most this
#: many re-evaluations at the estimated shift, stopping when a step is below
#: REGISTER_TOL of the pitch; each step at most REGISTER_MAX pitches.
REGISTER_ITERATIONS = 2
REGISTER_TOL = 1e-3
REGISTER_MAX = 2.0
#: ... and a move is undone when it raises the whitened residual per degree of
#: freedom at the nominal model by more than this share (1 %).
REGISTER_WORSE = 0.01
#: At most this many uncut points of a map are used.
MAX_UNCUT = 20000


def _clipped_sd(x: np.ndarray, clip: float = 5.0) -> tuple[float, float]:
    """Standard deviation about zero of ``x`` without its gross outliers.

    Values beyond ``clip`` robust sigmas (1.4826 MAD about the median) are left
    out; for Gaussian data that removes 6e-7 of them and biases the variance by
    1.5e-5, negligible. Returns the estimate (units of ``x``) and the fraction of
    values kept. Near-full efficiency (the MAD has 37 %), yet a few spikes (dust,
    dropouts) do not move it.
    """
    med = float(np.median(x))
    mad = 1.4826 * float(np.median(np.abs(x - med)))
    if not mad > 0:
        return float(np.sqrt(np.mean(x * x))), 1.0
    ok = np.abs(x - med) <= clip * mad
    return float(np.sqrt(np.mean(x[ok] ** 2))), float(ok.mean())


def _finite(r: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(r)):
        return np.full(r.shape, _DIVERGED)
    return r


def dirichlet2(delta: np.ndarray, n: int) -> np.ndarray:
    """``|sum_k exp(-2 pi i delta k / n)|^2`` for a rectangular window of n samples."""
    delta = np.asarray(delta, dtype=float)
    num = np.sin(np.pi * delta)
    den = np.sin(np.pi * delta / n)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (num / den) ** 2
    out = np.where(np.abs(den) < 1e-12, float(n) ** 2, out)
    return out


#: Relative sampling-rate difference up to which a record counts as sampled at the
#: controller rate (samples used as they are).
SAME_RATE = 1e-4


def same_rate(fs: float, case: CaseModel) -> bool:
    """Whether a record sampled at ``fs`` (Hz) is at the controller rate."""
    return abs(fs / case.fs - 1.0) <= SAME_RATE


#: Fraction of the Nyquist frequency up to which a record at another rate than the
#: controller's is compared: its acquisition's anti-alias filter rolls off below
#: the Nyquist frequency (delta-sigma DAQs pass 0.4-0.45 fs; scipy's default FIR
#: decimator is down 4 % at 0.85 and 37 % at 0.95 of it), and the model has no
#: such filter.
RESAMPLED_BAND = 0.8


def analysis_band(fs: float, case: CaseModel) -> tuple[float, float]:
    """Band ``(lo, hi)`` in Hz in which a record sampled at ``fs`` is compared.

    ``lo`` is the model's lowest frequency with noise power (``case.fs / 4096``,
    :meth:`CaseModel.noise_psd`). ``hi`` is the controller's Nyquist frequency
    for a record at the controller rate, else :data:`RESAMPLED_BAND` times the
    lower of the record's and the controller's Nyquist frequencies.
    """
    if same_rate(fs, case):
        return case.fs / 4096, 0.5 * case.fs
    return case.fs / 4096, RESAMPLED_BAND * 0.5 * min(fs, case.fs)


def _band_mask(f: np.ndarray, fs: float, case: CaseModel) -> np.ndarray:
    lo, hi = analysis_band(fs, case)
    return (f >= lo * (1 - 1e-9)) & (f > 0) & (f < hi * (1 - 1e-9))


def on_record_grid(
    case: CaseModel, t_rec: np.ndarray, simulate, inputs: dict | None = None
) -> dict:
    """A controller-rate simulation seen at a record's sample times.

    The loop runs at the controller rate ``case.fs`` from ``t_rec[0]`` (at rest
    there) to just past ``t_rec[-1]``: ``simulate(t_ctrl, **inputs_ctrl)``
    returns its arrays at the controller times ``t_ctrl`` (s), given the record's
    ``inputs`` (arrays at ``t_rec``, or None) splined onto them; each array is
    interpolated back to ``t_rec`` with a cubic spline. The deterministic
    responses compared this way (command tracking, the cut's force response) lie
    far below either Nyquist frequency, where the spline's error is of order
    ``(2 pi f / fs)^4 / 384`` (5e-5 at 12 kHz and 200 kHz); the record's own
    noise is never resampled.
    """
    from scipy.interpolate import CubicSpline

    t_rec = np.asarray(t_rec, dtype=float)
    m = int(math.floor((t_rec[-1] - t_rec[0]) * case.fs)) + 2
    t_ctrl = t_rec[0] + np.arange(m) / case.fs
    on_ctrl = {
        k: None if v is None else CubicSpline(t_rec, v)(t_ctrl)
        for k, v in (inputs or {}).items()
    }
    sim = simulate(t_ctrl, **on_ctrl)
    out = {}
    for k, v in sim.items():
        v = np.asarray(v)
        if v.shape == t_ctrl.shape and np.all(np.isfinite(v)):
            out[k] = CubicSpline(t_ctrl, v)(t_rec)
        elif v.shape == t_ctrl.shape:  # diverged: stays non-finite
            out[k] = np.full(t_rec.shape, np.nan)
        else:
            out[k] = v
    return out


def line_power(
    case: CaseModel,
    p: Model,
    freq: np.ndarray,
    n: int,
    fs: float,
    output: str = "fe",
) -> np.ndarray:
    """Expected periodogram (one-sided, m^2/Hz) of ``p``'s base lines at the bins.

    A line of base amplitude ``a`` at ``f0`` appears in ``output`` with amplitude
    ``A = a |H(f0)|`` and adds ``A^2 / 4 (D(k - k0)^2 + D(k + k0)^2) 2 / (fs n)`` to
    bin k of a rectangular-window periodogram (``D``: Dirichlet kernel) of ``n``
    samples at ``fs`` Hz.
    """
    out = np.zeros(np.shape(freq))
    lines = case.base_lines(p)
    pickup = case.sensor_lines(p) if output == "fe" else ()
    if not lines and not pickup:
        return out
    amp2 = _line_amplitudes(case, p, output) ** 2
    f0 = np.asarray([f for f, _ in lines + pickup], dtype=float)
    k = np.asarray(freq) * n / fs
    for j in range(f0.size):
        k0 = f0[j] * n / fs
        d2 = dirichlet2(k - k0, n) + dirichlet2(k + k0, n)
        out += amp2[j] / 4.0 * d2 * 2.0 / (fs * n)
    return out


#: Oversampling of the frequency grid on which the model PSD is integrated
#: against the window's kernel (4: the expected periodogram to 1e-8 relative on
#: the built-in loop, whose sharpest mode is several bins wide).
LEAKAGE_OVERSAMPLING = 4


def expected_periodogram(
    case: CaseModel, p: Model, freq: np.ndarray, n: int, fs: float,
    output: str = "fe",
) -> np.ndarray:
    """Expected rectangular-window periodogram (one-sided, m^2/Hz) of the noise.

    A record of ``n`` samples is a piece of a longer series, so its periodogram
    at bin k is the model PSD seen through the Fejer kernel, not the PSD at
    ``k fs / n``: ``E P_k = 2 / (fs n) sum_{|tau| < n} (n - |tau|) R(tau)
    exp(-2 pi i k tau / n)``, with ``R`` the autocovariance of the sampled
    series (the inverse transform of the model PSD on a grid
    :data:`LEAKAGE_OVERSAMPLING` times finer than the bins). Where the PSD falls
    steeply (towards the Nyquist frequency) the sidelobes of stronger bands add
    several per cent: a null record of the model is flagged without it.
    Records at another rate than the controller's keep the PSD at the bins (the
    model has no PSD above the controller's Nyquist frequency).
    """
    freq = np.asarray(freq, dtype=float)
    if not same_rate(fs, case):
        return case.noise_psd(p, freq, output)
    m = LEAKAGE_OVERSAMPLING * n
    fg = np.fft.rfftfreq(m, 1.0 / fs)
    sg = np.zeros(fg.shape)
    on = fg > 0
    sg[on] = case.noise_psd(p, fg[on], output)
    r = fs * np.fft.irfft(0.5 * sg, m)  # autocovariance, m^2
    tau = np.arange(n)
    c = (n - tau) * r[:n]
    e = (2.0 * np.real(np.fft.fft(c)) - c[0])[: n // 2 + 1] * 2.0 / (fs * n)
    k = np.rint(freq * n / fs).astype(int)
    return e[k]


def _line_amplitudes(case: CaseModel, p: Model, output: str) -> np.ndarray:
    """Amplitudes (m) of ``p``'s base lines in ``output`` (``fe`` or ``tool``),
    then (``fe`` only) of its sensor pickup lines, which the loop does not see."""
    lines = case.base_lines(p)
    f0 = np.asarray([f for f, _ in lines], dtype=float)
    amps = np.asarray([a for _, a in lines], dtype=float)
    if f0.size:
        amps = amps * np.abs(case.paths(p, f0)[("base", output)])
    if output == "fe":
        pickup = case.sensor_lines(p)
        amps = np.concatenate([amps, np.asarray([a for _, a in pickup], float)])
    return amps


class Context:
    """Shared state of one diagnosis: the case, memoised simulations.

    Parameters
    ----------
    case : CaseModel
        The case.
    """

    def __init__(self, case: CaseModel) -> None:
        self.case = case
        self._memo: dict = {}
        #: radial range (m) of the points of maps and profiles (spiral paths)
        self.radii: tuple[float, float] | None = None

    def memo(self, key, fn):
        """Return ``fn()`` cached under ``key`` (a small LRU of simulations)."""
        if key in self._memo:
            v = self._memo.pop(key)
            self._memo[key] = v
            return v
        v = fn()
        self._memo[key] = v
        if len(self._memo) > 96:
            self._memo.pop(next(iter(self._memo)))
        return v

    def cut_sim(self, p: Model, n: int, k0: int = 0) -> dict:
        """Cut of the case's toolpath: n samples from sample k0, at rest at k0."""
        n = int(n)
        k0 = int(k0)

        def run():
            t = (k0 + np.arange(n)) / self.case.fs
            return self.case.simulate_path(p, t)

        kp = p.key(SIM_GROUPS)
        for key, v in list(self._memo.items()):
            if (
                len(key) == 4
                and key[0] == kp
                and key[1] == "cut"
                and key[3] == k0
                and key[2] >= n
            ):
                return {k: a[:n] for k, a in v.items()}
        return self.memo((kp, "cut", n, k0), run)

    def trajectory(self, p: Model):
        """Deterministic tool trajectory of the toolpath under ``p``."""
        from ._surface import tool_trajectory, trajectory_samples

        k0, n, _ = trajectory_samples(self.case, radii=self.radii)
        return self.memo(
            (p.key(SIM_GROUPS), "traj", k0, n),
            lambda: tool_trajectory(self.case, p, sim=self.cut_sim(p, n, k0),
                                    radii=self.radii),
        )

    def cover(self, r: np.ndarray) -> None:
        """Widen the trajectory of a spiral path to points at radii ``r`` (m)."""
        r = np.asarray(r, dtype=float)
        if r.size == 0:
            return
        lo, hi = float(r.min()), float(r.max())
        if self.radii is not None:
            lo, hi = min(lo, self.radii[0]), max(hi, self.radii[1])
        self.radii = (lo, hi)


class Block:
    """Base class: a named channel of a recording.

    Attributes
    ----------
    recording : str
        Recording name.
    kind : str
        Recording kind.
    domain : str
        ``"spectrum"``, ``"time"``, ``"frf"``, ``"force"``, ``"map"`` or
        ``"profile"``.
    n : int
        Real observations (degrees of freedom of the deviance).
    groups : tuple of str
        Hook groups of the model (:meth:`Model.key`) the block depends on.
    model_free : bool
        Whether the block is built from its data alone (a rebuild at another
        model keeps it).
    time_span : float
        Longest coherent time span of the block's data in s (0: none).
    """

    groups: tuple[str, ...] = ()
    time_span: float = 0.0
    #: True when the block's construction reads no model (only its data)
    model_free: bool = False

    def __init__(self, recording: str, kind: str, domain: str, n: int) -> None:
        self.recording = recording
        self.kind = kind
        self.domain = domain
        self.n = n

    def residual(self, p: Model) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def deviance(self, p: Model) -> float:
        """Sum of squares of :meth:`residual`."""
        r = self.residual(p)
        return float(r @ r)


#: hook groups the loop simulation of a cut depends on
SIM_GROUPS = ("perturbation", "nonlinearity", "workpiece")


class SpectralBlock(Block):
    """Idle following-error records: Whittle deviance of the averaged periodogram.

    Parameters
    ----------
    ctx : Context
        Diagnosis context.
    name : str
        Recording name.
    fe : ndarray of shape (records, n)
        Following-error records in m.
    fs : float
        Sampling rate in Hz. Records at another rate than the controller's are
        compared at their own bins in :func:`analysis_band` (the model's
        spectrum is a function of frequency; the record is assumed anti-aliased).
    """

    def __init__(self, ctx: Context, name: str, fe: np.ndarray, fs: float) -> None:
        fe = np.atleast_2d(fe)
        r, n = fe.shape
        self.ctx = ctx
        self.fs = fs
        self.nrec = r
        self.nsamp = n
        f = np.fft.rfftfreq(n, 1.0 / fs)
        keep = _band_mask(f, fs, ctx.case)
        self.freq = f[keep]
        self.basis = record_basis(ctx.case, n, fs)  # low-band nuisance, out
        x = np.fft.rfft(project_low_band(fe, self.basis), axis=1)[:, keep]
        self.pbar = np.mean(np.abs(x) ** 2, axis=0) * 2.0 / (fs * n)
        self.spec_records = np.abs(x) ** 2 * 2.0 / (fs * n)
        super().__init__(
            recording=name,
            kind="following-error",
            domain="spectrum",
            n=int(self.freq.size),
        )

    groups = ("perturbation", "base_lines", "sensor_lines", "machine")
    #: built from the records alone (the expectation is evaluated at each model)
    model_free = True

    def expected(self, p: Model) -> np.ndarray:
        """Expected periodogram (m^2/Hz) at the block's bins under ``p``."""

        def run():
            s = expected_projected_periodogram(
                self.ctx.case, p, self.freq, self.nsamp, self.fs, self.basis)
            return s + line_power(self.ctx.case, p, self.freq, self.nsamp, self.fs)

        return self.ctx.memo((p.key(self.groups), "spec", self.recording), run)

    def residual(self, p: Model) -> np.ndarray:
        s = self.expected(p)
        if not np.all(np.isfinite(s)) or np.any(s <= 0):
            return np.full(self.n, _DIVERGED)
        u = self.pbar / s
        d = 2.0 * self.nrec * (u - 1.0 - np.log(u))
        return np.sign(u - 1.0) * np.sqrt(np.maximum(d, 0.0))


def _whiten_weights(
    ctx: Context, p: Model, freq: np.ndarray, n: int, fs: float
):
    """Inverse sd of the real (and imaginary) part of an n-sample DFT at ``fs``
    (the noise's expected periodogram, window leakage included)."""
    s = expected_periodogram(ctx.case, p, freq, n, fs)
    return 1.0 / np.sqrt(np.maximum(s, 1e-300) * n * fs / 4.0)


def _remove_lines(
    w: np.ndarray,
    cols: list[tuple[np.ndarray, np.ndarray]],
    amps: np.ndarray,
    sweeps: int = 3,
) -> np.ndarray:
    """Subtract sinusoids of known amplitude and free phase from ``w``.

    ``cols[j] = (c1, c2)`` are the whitened unit cosine and sine of line j, its
    model ``A_j (cos(phi) c1 - sin(phi) c2)``; the phases minimise the sum of
    squares (coordinate descent over lines, a 96-point scan refined by a parabola).
    """
    if not cols:
        return w
    phis = np.linspace(0.0, 2 * np.pi, 96, endpoint=False)
    cp, sp_ = np.cos(phis), np.sin(phis)
    models = [np.zeros_like(w) for _ in cols]
    r = w.copy()
    for _ in range(sweeps if len(cols) > 1 else 1):
        for j, ((c1, c2), a) in enumerate(zip(cols, amps, strict=True)):
            r = r + models[j]
            a1, a2 = float(r @ c1), float(r @ c2)
            g11, g22, g12 = float(c1 @ c1), float(c2 @ c2), float(c1 @ c2)
            f = -2 * a * (cp * a1 - sp_ * a2) + a * a * (
                cp * cp * g11 - 2 * sp_ * cp * g12 + sp_ * sp_ * g22
            )
            k = int(np.argmin(f))
            fm, f0, fp = f[k - 1], f[k], f[(k + 1) % f.size]
            den = fm - 2 * f0 + fp
            phi = phis[k] + (0.5 * (fm - fp) / den if den > 0 else 0.0) * (
                phis[1] - phis[0]
            )
            models[j] = a * (np.cos(phi) * c1 - np.sin(phi) * c2)
            r = r - models[j]
    return r


#: Bounds of a record's profiled noise level per source (power), dimensionless:
#: the recalibration's noise-level range.
NOISE_LEVEL_BOUNDS = (0.25, 4.0)
#: Periodogram cap (in units of its expectation) when profiling noise levels: an
#: exponential variable exceeds 12 with probability 6e-6.
NOISE_LEVEL_CAP = 12.0
#: Smallest share of a bin's noise power a source must reach somewhere in the
#: compared band for its level to be profiled.
NOISE_LEVEL_MIN_SHARE = 0.3
#: Likelihood-ratio statistic (chi2, 1 dof) a record's noise level must reach to
#: be taken off the model's: 3 sigma.
NOISE_LEVEL_LR = 9.0
#: Relative model error (of the deterministic response, per bin) a record's noise
#: level must not be mistaken for: bins where this share of the deterministic
#: response would exceed 0.3 of the noise power (whitened) do not set the level
#: (the command's harmonics, where a delay, a mode or a nonlinearity shows).
NOISE_LEVEL_MODEL_ERROR = 0.01
NOISE_LEVEL_SIGNAL = 0.3 / NOISE_LEVEL_MODEL_ERROR**2


class TimeBlock(Block):
    """Following-error records with a command and/or an external force.

    Residual: frequency-domain GLS of ``fe_measured - fe_simulated(p)`` with the
    noise PSD of the model the block was built at. Base-vibration lines of ``p``
    are deterministic sinusoids of free amplitude and phase in each record (their
    amplitude is set by the idle spectra); they are projected out, so a long record
    pins their frequency.
    """

    def __init__(
        self,
        ctx: Context,
        name: str,
        records: list[dict],
        fs: float,
        p_noise: Model,
    ) -> None:
        self.ctx = ctx
        self.fs = fs
        self.records = records
        self.meta = []
        self.bases = []
        tot = 0
        for rec in records:
            n = rec["fe"].size
            f = np.fft.rfftfreq(n, 1.0 / fs)
            keep = _band_mask(f, fs, ctx.case)
            # low-band nuisance (and an acquisition filter's settling at another
            # rate), projected out of data and model
            q = record_basis(ctx.case, n, fs, settle=True)
            w = _projected_whiten_weights(ctx, p_noise, f[keep], n, fs, q)
            self.meta.append((keep, w, f[keep]))
            self.bases.append(q)
            tot += 2 * int(keep.sum()) - _in_band_dof(q, keep)
        super().__init__(recording=name, kind="following-error", domain="time", n=tot)
        self.noise_factors = self._profile_noise_levels(p_noise)

    def _profile_noise_levels(self, p_noise: Model) -> dict[str, float]:
        """Noise level of each source in these records, relative to the model's.

        The disturbance PSDs are calibrations of one machine on one day (a gain
        setting, a cable, the floor moves them): a record's noise power per source
        is a nuisance within :data:`NOISE_LEVEL_BOUNDS` (power), fitted by the
        Whittle likelihood of its compared bins at the nominal deterministic
        model, each bin's periodogram capped at :data:`NOISE_LEVEL_CAP` times its
        expectation (lines and other deterministic misfits are narrow: they do not
        set a level). Sources with less than :data:`NOISE_LEVEL_MIN_SHARE` of
        any bin's power are left at the model's level. The whitening weights are
        scaled by the fitted level (``1 / sqrt(g)``) and the factors reported.
        """
        case = self.ctx.case
        us, shares = [], []
        self._quiet = []
        for i, rec in enumerate(self.records):
            keep, w, fk = self.meta[i]
            q = self.bases[i]
            x = np.fft.rfft(project_low_band(self.residual_time(p_noise, i), q))[keep]
            u = 0.5 * np.abs(x * w) ** 2  # Exp(1) per bin under the model
            pred = np.fft.rfft(project_low_band(self.predict(p_noise, i)["fe"], q))[keep]
            if not (np.all(np.isfinite(u)) and np.all(np.isfinite(pred))):
                return {}
            # only bins where a 1 % error of the deterministic response stays
            # below the noise: a model error there (a delay, a mode, a
            # nonlinearity at the command's harmonics) cannot pass for a level
            quiet = 0.5 * np.abs(pred * w) ** 2 < NOISE_LEVEL_SIGNAL
            parts = case.noise_psd_sources(p_noise, fk, "fe")
            tot = sum(parts.values())
            tot = np.where(tot > 0, tot, 1.0)
            us.append(np.minimum(u, NOISE_LEVEL_CAP)[quiet])
            shares.append({k: (v / tot)[quiet] for k, v in parts.items()})
            self._quiet.append(quiet)
        u = np.concatenate(us)
        if u.size < 64:
            return {}
        names = [k for k in shares[0]
                 if max(float(np.max(s[k], initial=0.0)) for s in shares)
                 >= NOISE_LEVEL_MIN_SHARE]
        if not names:
            return {}
        sh = np.array([np.concatenate([s[k] for s in shares]) for k in names])
        rest = 1.0 - sh.sum(axis=0)
        lo, hi = (math.log(b) for b in NOISE_LEVEL_BOUNDS)

        def nll(z):
            g = np.exp(z) @ sh + rest
            return float(np.sum(u / g + np.log(g)))

        res = sp.optimize.minimize(nll, np.zeros(len(names)), method="L-BFGS-B",
                                   bounds=[(lo, hi)] * len(names))
        a = np.exp(res.x)
        # a factor the records do not show at NOISE_LEVEL_LR (likelihood ratio,
        # the others at their fit) stays at the model's level
        out = {}
        for j, k in enumerate(names):
            z1 = res.x.copy()
            z1[j] = 0.0
            if 2.0 * (nll(z1) - res.fun) < NOISE_LEVEL_LR:
                a[j] = 1.0
            out[k] = float(a[j])
        for i in range(len(self.meta)):
            keep, w, fk = self.meta[i]
            parts = case.noise_psd_sources(p_noise, fk, "fe")
            tot = sum(parts.values())
            tot = np.where(tot > 0, tot, 1.0)
            g = np.ones(fk.size)
            for j, k in enumerate(names):
                g += (a[j] - 1.0) * parts[k] / tot
            self.meta[i] = (keep, w / np.sqrt(g), fk)
        return out

    groups = ("perturbation", "nonlinearity", "base_lines", "sensor_lines")

    @property
    def time_span(self) -> float:
        """Longest record in s."""
        return max(r["fe"].size for r in self.records) / self.fs

    def predict(self, p: Model, i: int) -> dict:
        """Simulated record i under ``p`` (dict of the simulator)."""
        rec = self.records[i]
        n = rec["fe"].size
        ref = rec.get("command", np.zeros(n))
        frc = rec.get("force")

        case = self.ctx.case
        if same_rate(self.fs, case):

            def run():
                return case.simulate(p, reference=ref, force=frc)

        else:  # the loop at the controller rate, seen at the record's samples

            def run():
                t = rec.get("t0", 0.0) + np.arange(n) / self.fs
                return on_record_grid(
                    case,
                    t,
                    lambda tc, **inp: case.simulate(p, **inp),
                    {"reference": ref, "force": frc},
                )

        key = (p.key(("perturbation", "nonlinearity")), "rec", self.recording, i)
        return self.ctx.memo(key, run)

    def residual_time(self, p: Model, i: int) -> np.ndarray:
        """Unwhitened residual of record i in m."""
        return self.records[i]["fe"] - self.predict(p, i)["fe"]

    def whitened(self, p: Model, i: int) -> np.ndarray:
        """Whitened residual spectrum of record i (complex, lines projected out)."""
        keep, w, _ = self.meta[i]
        q = self.bases[i]
        x = np.fft.rfft(project_low_band(self.residual_time(p, i), q))[keep] * w
        lines = self.ctx.case.base_lines(p) + self.ctx.case.sensor_lines(p)
        if lines:
            n = self.records[i]["fe"].size
            t = self.records[i].get("t0", 0.0) + np.arange(n) / self.fs
            cols = []
            for f0, _ in lines:
                pair = []
                for fn in (np.cos, np.sin):
                    c = np.fft.rfft(project_low_band(fn(2 * np.pi * f0 * t), q))[
                        keep] * w
                    pair.append(np.concatenate([c.real, c.imag]))
                cols.append(tuple(pair))
            v = _remove_lines(
                np.concatenate([x.real, x.imag]),
                cols,
                _line_amplitudes(self.ctx.case, p, "fe"),
            )
            m = x.size
            x = v[:m] + 1j * v[m:]
        return x

    def residual(self, p: Model) -> np.ndarray:
        out = []
        for i in range(len(self.meta)):
            x = self.whitened(p, i)
            out.append(x.real)
            out.append(x.imag)
        return _finite(np.concatenate(out))

    def whitened_time(self, p: Model, i: int) -> np.ndarray:
        """Whitened residual of record i as a time series (~ N(0, 1) samples)."""
        keep, w, _ = self.meta[i]
        n = self.records[i]["fe"].size
        y = np.zeros(n // 2 + 1, dtype=complex)
        y[keep] = self.whitened(p, i) * np.sqrt(n / 2.0)
        return np.fft.irfft(y, n)


class CutBlock(TimeBlock):
    """A cut: following error (GLS as :class:`TimeBlock`) of the toolpath cut."""

    groups = SIM_GROUPS + ("base_lines", "sensor_lines")

    def __init__(
        self, ctx: Context, name: str, data: dict, p_noise: Model
    ) -> None:
        """Build from a cut recording (``fs``, ``t``, ``fe``; loop at rest at t[0])."""
        fs = data["fs"]
        idx = np.rint(np.asarray(data["t"]) * fs).astype(np.int64)
        if idx[0] < 0:
            from ..errors import ConfigError

            raise ConfigError(f"{name}: cut time_s must start at or after 0 s")
        if np.any(np.diff(idx) != 1):
            from ..errors import ConfigError

            raise ConfigError(
                f"{name}: cut time_s must be one contiguous record at "
                "a constant sampling rate"
            )
        self.k0 = int(idx[0])
        self.n_sim = int(idx.size)
        rec = {"fe": np.asarray(data["fe"], dtype=float), "t0": self.k0 / fs}
        super().__init__(ctx, name, [rec], fs, p_noise)
        self.kind = "cut"

    def predict(self, p: Model, i: int = 0) -> dict:
        case = self.ctx.case
        if same_rate(self.fs, case):
            return self.ctx.cut_sim(p, self.n_sim, self.k0)
        t = (self.k0 + np.arange(self.n_sim)) / self.fs
        return self.ctx.memo(
            (p.key(SIM_GROUPS), "cut-resampled", self.recording),
            lambda: on_record_grid(case, t, lambda tc: case.simulate_path(p, tc)),
        )


#: Share of the compared band, from its top, whose periodogram median sets a force
#: record's white noise level: far above the lenslet harmonics where a model error
#: of the chip force lives, and inside the band an acquisition filter passes.
FORCE_LEVEL_BAND = 0.75


def white_level(x: np.ndarray, fs: float, hi: float) -> tuple[float, float, np.ndarray]:
    """White noise level of a record from its periodogram median.

    Parameters
    ----------
    x : ndarray of shape (n,)
        Record (any unit), its model subtracted.
    fs : float
        Sampling rate in Hz.
    hi : float
        Top of the compared band in Hz (the Nyquist frequency at the controller
        rate, :data:`RESAMPLED_BAND` of it otherwise).

    Returns
    -------
    sigma : float
        Standard deviation of the white noise per sample (x's unit): ``sqrt(median
        |X_k|^2 / (n ln 2))`` over the bins in the top :data:`FORCE_LEVEL_BAND` of
        ``(0, hi]`` (``|X_k|^2 / (n sigma^2)`` is exponential with median ln 2).
    var_log : float
        Variance of ``log sigma^2`` (the sample median of m exponential values:
        ``1 / (m ln(2)^2)``).
    keep : ndarray of bool
        The compared bins ``0 < f <= hi`` (below the Nyquist bin).
    """
    n = x.size
    f = np.fft.rfftfreq(n, 1.0 / fs)
    keep = (f > 0) & (f <= hi * (1 + 1e-12)) & (f < 0.5 * fs * (1 - 1e-12))
    xf = np.fft.rfft(x - np.mean(x))
    est = keep & (f >= (1.0 - FORCE_LEVEL_BAND) * hi)
    m = int(est.sum())
    if m < 8:
        d = np.diff(x)
        sig = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0)
        return float(sig), 2.0 / max(d.size, 1) / 0.77, keep
    sig2 = float(np.median(np.abs(xf[est]) ** 2)) / (n * math.log(2.0))
    return math.sqrt(max(sig2, 0.0)), 1.0 / (m * math.log(2.0) ** 2), keep


class ForceBlock(Block):
    """The force channel of a cut: measured minus the chip model, white noise.

    Compared in the frequency domain up to the band top of the record's rate
    (:func:`analysis_band`: an acquisition filter shapes the noise above it), with
    the white level of :func:`white_level` estimated at the nominal model."""

    def __init__(
        self, ctx: Context, cut: CutBlock, force: np.ndarray, p0: Model
    ) -> None:
        self.ctx = ctx
        self.cut = cut
        self.force = np.asarray(force, dtype=float)
        res = self.force - cut.predict(p0)["force"]
        hi = analysis_band(cut.fs, ctx.case)[1]
        sig, self.var_log_sigma, self.keep = white_level(res, cut.fs, hi)
        floor = 1e-4 * max(float(np.max(np.abs(self.force))), 1e-6)
        self.sigma = max(float(sig), floor)
        super().__init__(
            recording=cut.recording, kind="cut", domain="force",
            n=2 * int(self.keep.sum()),
        )

    groups = SIM_GROUPS

    def transform(self, x: np.ndarray) -> np.ndarray:
        """A force series (N) in the block's residual domain: real and imaginary
        parts of its compared bins over ``sqrt(n sigma^2 / 2)`` (white noise of
        the block's level gives N(0, 1) values)."""
        xf = np.fft.rfft(np.asarray(x, dtype=float))[self.keep]
        xf = xf / math.sqrt(0.5 * x.size * self.sigma**2)
        return np.concatenate([xf.real, xf.imag])

    def residual(self, p: Model) -> np.ndarray:
        return _finite(self.transform(self.force - self.cut.predict(p)["force"]))


class FRFBlock(Block):
    """A measured FRF: complex log-ratio residual with estimated relative noise."""

    groups = ("perturbation",)
    _OUT = {
        "frf-open-loop": "open_loop",
        "frf-closed-loop": ("reference", "sensor"),
        "frf-force": ("force", "sensor"),
    }

    def __init__(
        self,
        ctx: Context,
        name: str,
        kind: str,
        freq: np.ndarray,
        frf: np.ndarray,
        p0: Model,
    ) -> None:
        super().__init__(recording=name, kind=kind, domain="frf", n=0)
        self.ctx = ctx
        fs = ctx.case.fs
        keep = freq < 0.5 * fs
        self.freq = freq[keep]
        self.frf = frf[keep]
        self.key = self._OUT[kind]
        self.gain = kind in ("frf-open-loop", "frf-force")
        h0 = self.model(p0)
        lr = np.log(self.frf / h0)
        ph = np.angle(np.exp(1j * lr.imag))
        # a sign convention difference shows as a phase offset of pi
        self.flip = bool(np.abs(np.median(ph)) > np.pi / 2)
        if self.flip:
            self.frf = -self.frf
        r = self._raw(p0)
        m = r.size // 2
        d2 = np.concatenate([np.diff(r[:m], 2), np.diff(r[m:], 2)])
        sig = 1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0)
        self.sigma = max(float(sig), FRF_FLOOR)
        self.n = 2 * int(self.freq.size) - (1 if self.gain else 0)

    def model(self, p: Model) -> np.ndarray:
        """Model FRF at the block's frequencies under ``p``."""
        return self.ctx.memo(
            (p.key(("perturbation",)), "frf", self.recording),
            lambda: self.ctx.case.paths(p, self.freq)[self.key],
        )

    def _raw(self, p: Model) -> np.ndarray:
        h = self.model(p)
        with np.errstate(all="ignore"):
            lr = np.log(self.frf / h)
        ph = np.angle(np.exp(1j * lr.imag))
        re = lr.real
        if self.gain:
            re = re - re.mean()
        return np.concatenate([re, ph])

    def residual(self, p: Model) -> np.ndarray:
        return _finite(self._raw(p) / self.sigma)

    def gain_offset(self, p: Model) -> float:
        """Fitted constant gain (measured / model), dimensionless."""
        h = self.model(p)
        return float(np.exp(np.mean(np.log(np.abs(self.frf / h)))))


def tool_autocov_table(ctx: Context, p: Model) -> np.ndarray:
    """Autocovariance (m^2) of the stochastic tool error at integer sample lags.

    ``table[k]`` is the covariance at lag ``k / fs`` of the controller-rate tool
    error, from the synthesised real-error PSD above ``fs / 4096`` (the one
    :func:`servosurf.noise.realise` draws ``simulate``'s vibration from), on a
    periodic grid of 2^17 samples (0.66 s at 199.6 kHz).
    """
    fs = ctx.case.fs

    def table():
        n = 2**17
        f = np.fft.rfftfreq(n, 1.0 / fs)
        s = np.zeros(f.size)
        s[1:] = ctx.case.noise_psd(p, f[1:], "tool")
        r = np.fft.irfft(s, n) * fs / 2.0
        return r[: n // 2]

    return ctx.memo((p.key(("perturbation", "machine")), "toolcov"), table)


def tool_autocov(ctx: Context, p: Model, lags: np.ndarray) -> np.ndarray:
    """Autocovariance (m^2) of the stochastic tool error at ``lags`` (s)."""
    r = tool_autocov_table(ctx, p)
    k = np.abs(np.asarray(lags)) * ctx.case.fs
    return np.interp(k, np.arange(r.size), r, right=0.0)


def _interval_cov(k: np.ndarray, g0: np.ndarray, g1: np.ndarray,
                  rt: np.ndarray) -> np.ndarray:
    """Covariance (m^2) of one segment's interval statistics.

    A statistic is ``g0 n_k + g1 n_(k+1)`` of the controller-rate tool error
    ``n`` at interval ``k``; with ``r(j)`` its autocovariance at lag ``j`` samples
    (``rt``, zero beyond the table):
    ``C_ij = (g0_i g0_j + g1_i g1_j) r(k_i - k_j) + A_ij + A_ji``,
    ``A_ij = g0_i g1_j r(k_i - k_j - 1)``.
    """
    rtp = np.append(rt, 0.0)
    d = k[:, None] - k[None, :]
    c0 = rtp[np.minimum(np.abs(d), rt.size)]
    a = np.outer(g0, g1) * rtp[np.minimum(np.abs(d - 1), rt.size)]
    return (np.outer(g0, g0) + np.outer(g1, g1)) * c0 + a + a.T


def _lower_inverse(ch: np.ndarray) -> np.ndarray:
    """Inverse of a lower-triangular matrix (LAPACK ``dtrtri``)."""
    inv, info = sp.linalg.lapack.dtrtri(ch, lower=1)
    if info != 0:
        return sp.linalg.solve_triangular(ch, np.eye(ch.shape[0]), lower=True)
    return np.tril(inv)


def _lower_block_diag(blocks: list[np.ndarray]) -> "sp.sparse.csr_matrix":
    """Block-diagonal CSR matrix of dense lower-triangular blocks (their lower
    triangles stored, zeros included)."""
    if not blocks:
        return sp.sparse.csr_matrix((0, 0))
    sizes = [b.shape[0] for b in blocks]
    offs = np.concatenate([[0], np.cumsum(sizes)])
    data, indices, nnz = [], [], [np.zeros(1, dtype=np.int64)]
    for b, o in zip(blocks, offs[:-1], strict=True):
        r, c = np.tril_indices(b.shape[0])
        data.append(b[r, c])
        indices.append(c + o)
        nnz.append(np.arange(1, b.shape[0] + 1, dtype=np.int64))
    row_nnz = np.concatenate(nnz)
    indptr = np.cumsum(row_nnz)
    n = int(offs[-1])
    return sp.sparse.csr_matrix(
        (np.concatenate(data), np.concatenate(indices), indptr), shape=(n, n))


def _tridiagonal(c: np.ndarray, b: np.ndarray):
    """``c = Q H Q^T`` (symmetric ``c``; LAPACK ``dsytrd``, lower): the diagonal
    and off-diagonal of the tridiagonal ``H`` and ``Q^T b``."""
    n = c.shape[0]
    if n < 2:
        return np.diag(c).copy(), np.zeros(0), np.asarray(b, dtype=float).copy()
    lw, _ = sp.linalg.lapack.dsytrd_lwork(n, lower=1)
    a, d, e, tau, info = sp.linalg.lapack.dsytrd(c, lower=1, lwork=int(lw))
    if info != 0:
        raise np.linalg.LinAlgError(f"dsytrd failed (info {info})")
    z = np.array(b, dtype=float)
    # Q = H(1) ... H(n-1), H(i) = I - tau_i v_i v_i^T with v_i = (0.., 1, a[i+1:, i]):
    # Q^T b applies H(1) first
    for i in range(n - 1):
        v = a[i + 1:, i].copy()
        v[0] = 1.0
        z[i + 1:] -= tau[i] * v * (v @ z[i + 1:])
    return d, e, z


def _tridiagonal_quad(d: np.ndarray, e: np.ndarray, z: np.ndarray, k: float,
                      s2: float) -> float:
    """``z^T (k H + s2 I)^-1 z`` for the tridiagonal ``H`` of (``d``, ``e``)."""
    if d.size < 2:
        return float(np.sum(z * z / np.maximum(k * d + s2, 1e-300)))
    ab = np.empty((2, d.size))
    ab[0, 0] = 0.0
    ab[0, 1:] = k * e
    ab[1] = k * d + s2
    try:
        x = sp.linalg.solveh_banded(ab, z, check_finite=False)
    except np.linalg.LinAlgError:
        ab3 = np.zeros((3, d.size))
        ab3[0, 1:] = k * e
        ab3[1] = k * d + s2
        ab3[2, :-1] = k * e
        x = sp.linalg.solve_banded((1, 1), ab3, z, check_finite=False)
    return float(z @ x)


#: Cut points whose pass times are further apart than this (s) are treated as
#: independent noise segments (different revolutions or rings).
SEGMENT_GAP = 0.02


def _curved(tx: np.ndarray, ty: np.ndarray) -> bool:
    """Whether a profile's direction turns by more than 1 mrad along it."""
    if tx.size < 2:
        return False
    ang = np.unwrap(np.arctan2(ty, tx))
    return bool(np.ptp(ang) > 1e-3)


class PointsBlock(Block):
    """A surface map or profile: heights at points versus the pointwise model.

    Parameters
    ----------
    ctx : Context
        Diagnosis context.
    name, kind : str
        Recording name and kind (``surface`` or ``profile``).
    x, y : ndarray of shape (n,)
        Point coordinates in the workpiece frame, m.
    z : ndarray of shape (n,)
        Measured heights in m (finite).
    p0 : Model
        Model the noise weighting and nuisance columns are built at.
    grid : tuple, optional
        ``(shape, flat_index)`` of a map, for pictures.
    along : ndarray of shape (n,), optional
        Position along a profile in m.
    form_order : int, default: 1
        Order of the polynomial form profiled out with the nuisance (1: piston
        and tilt; higher: a form the instrument removed from the recording).
    """

    #: what the heights depend on (the lines are projected out of the residual)
    predict_groups = SIM_GROUPS + ("path_z", "tool", "cutting_rules", "surface")
    groups = predict_groups + ("base_lines",)

    @property
    def time_span(self) -> float:
        """Span of the pass times of the cut points in s."""
        t = self.tpass[np.isfinite(self.tpass)]
        return float(np.ptp(t)) if t.size else 0.0

    def __init__(
        self,
        ctx: Context,
        name: str,
        kind: str,
        x: np.ndarray,
        y: np.ndarray,
        z: np.ndarray,
        p0: Model,
        grid=None,
        along: np.ndarray | None = None,
        form_order: int = 1,
    ) -> None:
        #: polynomial order of the form profiled out (1: piston and tilt)
        self.form_order = int(form_order)

        super().__init__(
            recording=name,
            kind=kind,
            domain="map" if kind == "surface" else "profile",
            n=0,
        )
        self.ctx = ctx
        self.grid = grid
        self.z_all = z
        self.along = along
        #: lateral registration of the recording in the workpiece frame, m: the
        #: shift (x, y) and, on a ring profile, along the profile, found by
        #: :meth:`_register`; the model is evaluated at the registered points
        self.registration = {"x_m": 0.0, "y_m": 0.0, "along_m": 0.0}
        self._setup(x, y, z, p0)
        self._register(x, y, z, p0)

    def _setup(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, p0: Model) -> None:
        """Points kept, their passes, the nuisance and the noise weighting at
        points ``(x, y)`` (m, workpiece frame)."""
        ctx = self.ctx
        self.x_all, self.y_all = x, y
        #: generation of the point set (memo keys of the model heights)
        self._points_gen = getattr(self, "_points_gen", -1) + 1
        case = ctx.case
        ctx.cover(np.hypot(x, y))
        from ._surface import PointSet, surface_heights

        pts = PointSet(case, x, y)
        traj = ctx.trajectory(p0)

        h0, k0, hmin, gap = surface_heights(case, pts, p0, traj, return_pass=True)
        self.pts_all = pts
        cut = k0 >= 0
        # leave out the cut edge (where the boundary moves with any effect) and
        # the points two passes compete for (cusps of a facing cut): there the
        # tool noise decides which pass leaves the surface, a min of two noisy
        # heights the Gaussian model cannot describe
        rt = tool_autocov_table(ctx, p0)
        ambiguous = gap < AMBIGUITY_SIGMAS * math.sqrt(2.0 * max(rt[0], 0.0))
        # ... and a band around the cut boundary (the rim of a lenslet): there the
        # surface has a kink, which an instrument's optical and pixel transfer
        # function rounds over about its resolution (not described by the
        # smoothing nuisance below)
        near_edge = np.zeros(cut.shape, dtype=bool)
        for ddx, ddy in ((EDGE_BAND, 0.0), (-EDGE_BAND, 0.0), (0.0, EDGE_BAND),
                         (0.0, -EDGE_BAND)):
            kd = surface_heights(case, PointSet(case, x + ddx, y + ddy), p0, traj,
                                 return_pass=True)[1]
            near_edge |= (kd >= 0) != cut
        keep = (~(np.abs(hmin - case.top) < EDGE_MARGIN) & ~(cut & ambiguous)
                & ~near_edge & ~self._near_border(x, y))
        # the uncut top only carries instrument noise, piston and tilt: thin it
        unc = np.nonzero(keep & ~cut)[0]
        if unc.size > MAX_UNCUT:
            drop = np.setdiff1d(unc, unc[:: int(math.ceil(unc.size / MAX_UNCUT))])
            keep[drop] = False
        self.keep = keep
        self.pts = PointSet(case, x[keep], y[keep])
        self.z = z[keep]
        self.cut = cut[keep]
        self.k = k0[keep]
        tp = self.pts.t[np.arange(self.pts.n), np.maximum(self.k, 0)]
        self.tpass = np.where(self.cut, tp, np.nan)
        self._build_weights(p0, h0[keep])
        self.n = int(self.dof)

    def _register(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, p0: Model
                  ) -> None:
        """Move the points to the recording's registration, estimated at ``p0``.

        The registration columns of the nuisance are derivatives: a first-order
        model of a shift. A shift of a fraction of a micrometre over a lenslet's
        curvature leaves a second-order residual of about the instrument noise,
        structured like an effect: a 0.23 um rotation of a ring profile left a
        residual that projected -5.4 sd on a thermal drift's column, and was named
        as one (independent null case_0035, seed 3). On a lenslet path (each
        point cut by one pass, smooth heights inside a lenslet) the shift is
        therefore estimated by GLS at ``p0`` with the nuisance, the points moved
        by it and the block rebuilt there (at most :data:`REGISTER_ITERATIONS`
        times, until a step is below :data:`REGISTER_TOL` of the pitch; steps
        capped at :data:`REGISTER_MAX` pitches); the derivative columns stay in
        the nuisance for what is left.

        Not on facing cuts: their heights are the lowest of competing passes, the
        linearised shift of a cusp field does not converge, and it absorbs
        effects (a minimum chip thickness raising the ridges moved the map by
        0.3 um and its fitted value by 27 %). A move that raises the whitened
        residual per degree of freedom by more than :data:`REGISTER_WORSE` is
        undone.
        """
        if self.ctx.case.toolpath.kind != "lenslet":
            return
        tx, ty = self._tangent(x, y)
        curved = self.kind == "profile" and _curved(tx, ty)
        dev0 = float(np.sum(self.residual(p0) ** 2)) / max(self.n, 1)
        sx = sy = sa = 0.0
        for _ in range(REGISTER_ITERATIONS):
            cols = self._reg_cols
            if not cols:
                break
            r0 = self.z - self._predict(p0)
            coef, *_ = np.linalg.lstsq(self._whiten(self.X_raw), self._whiten(r0),
                                       rcond=None)
            step = {k: float(coef[j]) * 1e-6 for k, j in cols.items()}
            if not all(np.isfinite(v) for v in step.values()):
                break
            cap = REGISTER_MAX * self._pitch
            step = {k: float(np.clip(v, -cap, cap)) for k, v in step.items()}
            if max(abs(v) for v in step.values()) < REGISTER_TOL * self._pitch:
                break
            sx += step.get("x", 0.0)
            sy += step.get("y", 0.0)
            sa += step.get("along", 0.0) if curved else 0.0
            self._setup(x + sx + sa * tx, y + sy + sa * ty, z, p0)
        if sx == sy == sa == 0.0:
            return
        dev1 = float(np.sum(self.residual(p0) ** 2)) / max(self.n, 1)
        if not dev1 <= dev0 * (1.0 + REGISTER_WORSE):
            self._setup(x, y, z, p0)
            return
        self.registration = {"x_m": sx, "y_m": sy, "along_m": sa}

    # ------------------------------------------------------------ build
    def _near_border(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Points within :data:`EDGE_BAND` of the border of the valid data.

        An instrument's smoothing is one-sided there (the map's edge, a void or
        a dropout): its transfer function differs from the interior's.
        """
        if self.grid is None:
            d = np.hypot(np.diff(x), np.diff(y))
            step = float(np.median(d)) if d.size else 1.0
            m = int(math.ceil(EDGE_BAND / max(step, 1e-12)))
            out = np.zeros(x.size, dtype=bool)
            out[:m] = out[-m:] = True
            if x.size > 1:  # gaps in a profile
                gap = np.nonzero(d > 1.5 * step)[0]
                for g in gap:
                    out[max(g - m + 1, 0) : g + m + 1] = True
            return out
        import scipy.ndimage as ndi

        shape, flat = self.grid
        valid = np.zeros(shape[0] * shape[1], dtype=bool)
        valid[flat] = True
        valid = valid.reshape(shape)
        dx = float(np.min(np.abs(np.diff(np.unique(x))))) if np.unique(x).size > 1 \
            else EDGE_BAND
        m = int(math.ceil(EDGE_BAND / max(dx, 1e-12)))
        inner = ndi.binary_erosion(np.pad(valid, m, constant_values=False),
                                   structure=np.ones((2 * m + 1, 2 * m + 1)))
        inner = inner[m:-m, m:-m] if m else inner
        return ~inner.ravel()[flat]

    def _tangent(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit direction of a profile at each point (along increasing index; a
        map: the x direction)."""
        if self.kind != "profile" or x.size < 2:
            return np.ones_like(x), np.zeros_like(x)
        gx, gy = np.gradient(x), np.gradient(y)
        nrm = np.hypot(gx, gy)
        ok = nrm > 0
        tx = np.where(ok, gx / np.where(ok, nrm, 1.0), 1.0)
        ty = np.where(ok, gy / np.where(ok, nrm, 1.0), 0.0)
        return tx, ty

    def _nuisance(self, p0: Model) -> np.ndarray:
        x, y = self.pts.x, self.pts.y
        cols = [np.ones_like(x)]
        if self.kind == "surface":
            u, v = (x - x.mean()) / 1e-3, (y - y.mean()) / 1e-3
            cols += [u ** (k - j) * v ** j for k in range(1, self.form_order + 1)
                     for j in range(k + 1)]
        else:
            s = self.along[self.keep] if self.along is not None else x
            u = (s - s.mean()) / 1e-3
            cols += [u ** k for k in range(1, self.form_order + 1)]
        # lateral registration: derivative of the model heights along x and y
        from ._surface import PointSet, surface_heights

        traj = self.ctx.trajectory(p0)
        d = 0.05 * self._pitch
        #: column index of each registration derivative (coefficient in um)
        self._reg_cols = {}
        for name, dx, dy in (("x", d, 0.0), ("y", 0.0, d)):
            if self.kind == "profile" and self.along is None and dy:
                continue
            hp = surface_heights(
                self.ctx.case, PointSet(self.ctx.case, x + dx, y + dy), p0, traj
            )
            hm = surface_heights(
                self.ctx.case, PointSet(self.ctx.case, x - dx, y - dy), p0, traj
            )
            self._reg_cols[name] = len(cols)
            cols.append((hp - hm) / (2 * d) * 1e-6)
        tx, ty = self._tangent(x, y)
        if self.kind == "profile" and _curved(tx, ty):
            self._reg_cols["along"] = len(cols)
            # a curved (ring) profile's start-angle registration: a shift along
            # the profile at every point (a rotation about the spindle axis),
            # which translations of the whole circle cannot represent
            hp = surface_heights(
                self.ctx.case, PointSet(self.ctx.case, x + d * tx, y + d * ty), p0,
                traj)
            hm = surface_heights(
                self.ctx.case, PointSet(self.ctx.case, x - d * tx, y - d * ty), p0,
                traj)
            cols.append((hp - hm) / (2 * d) * 1e-6)
        # the instrument's smoothing (optical PSF, pixel integration, resampling):
        # to first order any symmetric kernel of variance s^2 adds (s^2 / 2) times
        # the Laplacian of the heights, profiled out like piston and tilt
        h0 = surface_heights(self.ctx.case, self.pts, p0, traj)
        dl = self._pitch
        lap = -2.0 * h0 if self.kind == "profile" else -4.0 * h0
        offsets = ((dl, 0.0), (-dl, 0.0), (0.0, dl), (0.0, -dl))
        if self.kind == "profile":  # along the profile at each point
            offsets = ((dl * tx, dl * ty), (-dl * tx, -dl * ty))
        for ddx, ddy in offsets:
            lap = lap + surface_heights(
                self.ctx.case, PointSet(self.ctx.case, x + ddx, y + ddy), p0, traj)
        cols.append(lap / dl**2 * 1e-12)
        return np.column_stack(cols)

    def _build_weights(self, p0: Model, h0: np.ndarray) -> None:
        fs = self.ctx.case.fs
        n = self.z.size
        if self.kind == "surface":
            self._pitch = float(
                min(
                    np.min(np.abs(np.diff(np.unique(self.x_all))))
                    if np.unique(self.x_all).size > 1
                    else 1e-6,
                    1e-3,
                )
            )
        else:
            d = np.hypot(np.diff(self.x_all), np.diff(self.y_all))
            self._pitch = float(np.median(d)) if d.size else 1e-6
        # The tool height at a cut point is the controller-rate tool error
        # interpolated linearly between the two samples around its pass time (the
        # sweep interpolates the sampled path): z_i = (1 - a_i) n_k + a_i n_(k+1).
        # Points are grouped by their interval k; in each group the residual is
        # split exactly into its projection on the columns (1 - a, a), which
        # carries the tool noise (at most two statistics per interval, whose
        # covariance follows from the tool error's autocovariance at integer
        # lags), and the orthogonal rest, which carries only instrument noise.
        cut = self.cut
        bins = np.full(n, -1, dtype=np.int64)
        a = np.zeros(n)
        ks = np.zeros(0, dtype=np.int64)
        if cut.any():
            x = self.tpass[cut] * fs
            k = np.floor(x)
            a[cut] = x - k
            ks, inv = np.unique(k.astype(np.int64), return_inverse=True)
            bins[cut] = inv
        self.bins = bins
        self.a = a
        self.bin_sample = ks
        nb = int(ks.size)
        self.nb = nb
        bc = bins[cut]
        ac = a[cut]
        counts = np.bincount(bc, minlength=nb).astype(float)
        self.counts = counts
        self.tb = (
            np.bincount(bc, weights=self.tpass[cut], minlength=nb)
            / np.maximum(counts, 1)
            if nb
            else np.zeros(0)
        )
        s11 = np.bincount(bc, weights=(1 - ac) ** 2, minlength=nb)
        s12 = np.bincount(bc, weights=(1 - ac) * ac, minlength=nb)
        s22 = np.bincount(bc, weights=ac**2, minlength=nb)
        l11 = np.sqrt(s11)
        l21 = np.where(l11 > 0, s12 / np.maximum(l11, 1e-300), 0.0)
        l22sq = s22 - l21**2
        rank2 = (counts >= 2) & (l22sq > 1e-8 * np.maximum(s22, 1e-300))
        l22 = np.where(rank2, np.sqrt(np.maximum(l22sq, 0.0)), 0.0)
        self._gram = (s11, s12, s22, l11, l21, l22, rank2)
        # statistics: one per interval (a projection on 1 - a), a second where
        # the interval's points span two directions
        self.stat_bin = np.concatenate([np.arange(nb), np.nonzero(rank2)[0]])
        self.stat_comp = np.concatenate(
            [np.zeros(nb, dtype=np.int64), np.ones(int(rank2.sum()), dtype=np.int64)]
        )
        n_stats = int(self.stat_bin.size)
        self.n_within = int(cut.sum()) - n_stats
        # leverage of each cut point in its interval (for the sigma estimate)
        det = s11 * s22 - s12**2
        lev = np.zeros(n)
        if nb:
            x1, x2 = 1 - ac, ac
            r2 = rank2[bc]
            with np.errstate(invalid="ignore", divide="ignore"):
                h2 = (x1**2 * s22[bc] - 2 * x1 * x2 * s12[bc] + x2**2 * s11[bc]) / (
                    det[bc])
                h1 = x1**2 / s11[bc]
            lev[cut] = np.where(r2, h2, h1)
        self._lev = lev
        # instrument noise from the nominal residual: within-interval spread and
        # uncut. A clipped standard deviation (points beyond 5 robust sigma left
        # out), not the MAD: the omnibus RMS tests of _locate compare variances at
        # ~1e4 dof, where the MAD's 37 % efficiency alone spread the along-cut
        # statistic ~1.3x wider than chi2 (measured on null cases). The estimate's
        # own uncertainty enters those tests through ``sigma_dof`` and overlaps.
        X = self._nuisance(p0)
        self.X_raw = X
        r0 = self.z - self._predict(p0)
        coef, *_ = np.linalg.lstsq(X, r0, rcond=None)
        r0 = r0 - X @ coef
        dev = []
        n_within = 0
        if nb:
            w0 = self._within(r0[:, None])[:, 0]
            ok = lev[cut] < 1 - 1e-9
            dev.append(w0[ok] / np.sqrt(1 - lev[cut][ok]))
            n_within = self.n_within
        n_uncut = 0
        if (~cut).sum() > 8:
            u = r0[~cut]
            dev.append(u - np.median(u))
            n_uncut = u.size
        allv = np.concatenate(dev) if dev else np.zeros(0)
        # tool-noise covariance of the interval statistics per segment of
        # connected time (sigma^2 is added once estimated)
        tool_cov = []
        if nb:
            rt = tool_autocov_table(self.ctx, p0)
            b_of = self.stat_bin
            g0 = np.where(self.stat_comp == 0, l11[b_of], 0.0)
            g1 = np.where(self.stat_comp == 0, l21[b_of], l22[b_of])
            kk = ks[b_of]
            order = np.argsort(kk, kind="stable")
            gap = max(int(SEGMENT_GAP * fs), 1)
            cuts = np.nonzero(np.diff(kk[order]) > gap)[0] + 1

            for seg in np.split(order, cuts):
                tool_cov.append((seg, _interval_cov(kk[seg], g0[seg], g1[seg], rt)))
        n_stats_dof = 0.0
        self.ml_rho2 = 0.0
        sig, dof_sig = None, math.inf
        self.tool_scale = 1.0
        self.stats_sigma = None
        if allv.size >= 16 and allv.size >= min(MIN_SIGMA_POINTS, 0.5 * n_stats):
            sig, kept = _clipped_sd(allv)
            dof_sig = (n_within + n_uncut) * kept
            if tool_cov:
                # the tool-noise level is a nuisance within TOOL_SCALE_BOUNDS: the
                # disturbance PSDs are calibrations, and an instrument's resampling
                # between rows smooths the tool error along the cut
                self.stats_sigma, self.tool_scale, _ = self._noise_ml(
                    r0, tool_cov, allv, sigma=max(sig, MAP_FLOOR))
        elif tool_cov:
            # too few instrument-only values (a facing map: one or two points per
            # interval, no uncut top): maximum likelihood of the statistics
            # together with what there is, sigma and tool-noise scale jointly
            sig, self.tool_scale, n_stats_dof = self._noise_ml(r0, tool_cov, allv)
            self.stats_sigma = sig
            dof_sig = n_stats_dof + n_within + n_uncut
        if sig is None or not np.isfinite(sig) or not sig > 0:
            d = np.diff(r0)
            sig, kept = _clipped_sd(d - np.median(d))
            sig /= math.sqrt(2.0)
            # var(sum of squared first differences) = 12 n sigma^4: 2n/3 dof
            dof_sig = 2.0 * d.size * kept / 3.0
            n_within = n_uncut = 0
        if not sig > MAP_FLOOR:
            dof_sig = math.inf  # the floor, not an estimate
            n_stats_dof = 0.0
        self.sigma = max(float(sig), MAP_FLOOR)
        #: dof of the instrument-variance estimate, and how many of them came
        #: from the within-interval spread, the uncut top and the statistics
        self.sigma_dof = float(dof_sig)
        self.sigma_parts = {"within": n_within, "uncut": n_uncut,
                            "stats": int(round(n_stats_dof))}
        # whitening of the statistics by the block-diagonal inverse Cholesky
        # factor of their covariance (sparse)
        self.segments = []
        self.wbins = None
        self.instrument_share = 0.0
        if tool_cov:
            s_st = max(self.stats_sigma or self.sigma, self.sigma)
            for seg, c in tool_cov:
                c = self.tool_scale * c
                c[np.diag_indices_from(c)] += s_st**2
                try:
                    ch = np.linalg.cholesky(c)
                except np.linalg.LinAlgError:
                    ch = np.linalg.cholesky(
                        c + np.eye(seg.size) * 1e-9 * np.trace(c) / seg.size
                    )
                self.segments.append((seg, ch))
            self.seg_index = np.concatenate([seg for seg, _ in self.segments])
            self.wbins = _lower_block_diag(
                [_lower_inverse(ch) for _seg, ch in self.segments])
            # share of the whitened statistics' power that scales with the
            # instrument variance: sigma^2 tr(C^-1) / m on average (what an
            # error in sigma moves in the along-cut test)
            self.instrument_share = float(
                s_st**2 * self.wbins.multiply(self.wbins).sum() / n_stats
            )
        wx = self._whiten(X)
        q, _ = np.linalg.qr(wx)
        self.q = q
        self.dof = n - q.shape[1]

    def _noise_ml(self, r0, tool_cov, allv, sigma=None):
        """Tool-noise scale (and, when ``sigma`` is None, the instrument sigma) by
        maximum likelihood of the interval statistics.

        ``nll = sum_seg [log det(k T + s^2 I) + b^T (k T + s^2 I)^-1 b]
        + sum(v^2) / s^2 + n log s^2`` over at most :data:`ML_SEGMENTS` segments
        (eigendecomposition of each tool covariance T once), ``v`` the
        instrument-only values, ``k`` in :data:`TOOL_SCALE_BOUNDS`.

        Returns
        -------
        sigma : float
            White level of the statistics in m (at least ``sigma`` when given).
        scale : float
            Tool-noise power scale ``k`` (dimensionless).
        stats_dof : float
            Equivalent dof the statistics carry about ``log s^2``.
        """
        st = self._stats(r0[:, None])[:, 0]
        # each segment's covariance T = Q H Q^T with H tridiagonal (Householder,
        # 4/3 n^3 instead of an eigendecomposition's ~9 n^3): log det(k T + s^2 I)
        # from H's eigenvalues and b^T (k T + s^2 I)^-1 b = z^T (k H + s^2 I)^-1 z,
        # z = Q^T b, by a banded solve per evaluation
        parts = []
        step = max(1, len(tool_cov) // ML_SEGMENTS)
        for seg, c in tool_cov[::step][:ML_SEGMENTS]:
            parts.append(_tridiagonal(c, st[seg]))
        lam = np.maximum(np.concatenate([
            sp.linalg.eigh_tridiagonal(d_, e_, eigvals_only=True) if d_.size > 1
            else d_ for d_, e_, _z in parts]), 0.0)
        ssv = float(allv @ allv) if allv.size else 0.0
        nv = float(allv.size)
        wseg = len(tool_cov) / max(len(parts), 1)
        lo_k, hi_k = (math.log(b_) for b_ in TOOL_SCALE_BOUNDS)

        def quad(k, s2):
            return sum(_tridiagonal_quad(d_, e_, z_, k, s2) for d_, e_, z_ in parts)

        def nll(lk, ls2):
            s2, k = math.exp(ls2), math.exp(lk)
            d = k * lam + s2
            out = float(wseg * (np.sum(np.log(d)) + quad(k, s2)))
            if sigma is None:
                out += ssv / s2 + nv * ls2
            return out

        if sigma is not None:
            # the statistics' own white level: at least the instrument sigma of
            # the within-interval spread (more where the instrument resampled
            # between rows, which the interval model leaves out)
            lo_s = 2.0 * math.log(sigma)
            bnd_s = (lo_s, lo_s + math.log(4.0))
            res = sp.optimize.minimize(
                lambda z: nll(z[0], z[1]), x0=[0.0, lo_s + 0.01],
                bounds=[(lo_k, hi_k), bnd_s], method="L-BFGS-B")
        else:
            # the median squared projection of the statistics on T's eigenvectors
            # (H's eigenvectors applied to z): their typical variance
            proj = [
                (sp.linalg.eigh_tridiagonal(d_, e_)[1].T @ z_) ** 2 if d_.size > 1
                else z_**2 for d_, e_, z_ in parts]
            proj = np.concatenate(proj) if proj else np.zeros(0)
            guess = float(np.median(proj) if proj.size else 1e-20)
            bnd_s = (math.log(MAP_FLOOR**2 * 1e-2), math.log(max(guess, 1e-18) * 1e2))
            res = sp.optimize.minimize(
                lambda z: nll(z[0], z[1]), x0=[0.0, 0.5 * sum(bnd_s)],
                bounds=[(lo_k, hi_k), bnd_s], method="L-BFGS-B")
        lk, ls2 = (float(v) for v in res.x)
        s2, k = math.exp(ls2), math.exp(lk)
        w = s2 / (k * lam + s2)
        stats_dof = float(wseg * np.sum(w**2))
        # squared correlation of the along-cut sum of squares with the ML score
        # (near 1: the estimate fixes that statistic, which then tells nothing);
        # a scale at its bound leaves the statistic free
        at_bound = min(abs(lk - lo_k), abs(lk - hi_k)) < 1e-3
        self.ml_rho2 = 0.0 if at_bound else 1.0
        return math.sqrt(s2), k, stats_dof

    def _stats(self, rr: np.ndarray) -> np.ndarray:
        """Interval statistics ``L^-1 X^T r`` of cut residuals (n_stats, m)."""
        s11, s12, s22, l11, l21, l22, rank2 = self._gram
        b = self.bins[self.cut]
        ac = self.a[self.cut]
        nb = self.nb
        m = rr.shape[1]
        t1 = np.zeros((nb, m))
        t2 = np.zeros((nb, m))
        for j in range(m):
            rc = rr[self.cut, j]
            t1[:, j] = np.bincount(b, weights=(1 - ac) * rc, minlength=nb)
            t2[:, j] = np.bincount(b, weights=ac * rc, minlength=nb)
        beta1 = t1 / l11[:, None]
        beta2 = (t2[rank2] - l21[rank2, None] * beta1[rank2]) / l22[rank2, None]
        return np.concatenate([beta1, beta2], axis=0)

    def _within(self, rr: np.ndarray) -> np.ndarray:
        """Cut residuals minus their projection on each interval's (1 - a, a)."""
        s11, s12, s22, l11, l21, l22, rank2 = self._gram
        b = self.bins[self.cut]
        ac = self.a[self.cut]
        nb = self.nb
        out = np.empty((b.size, rr.shape[1]))
        det = s11 * s22 - s12**2
        for j in range(rr.shape[1]):
            rc = rr[self.cut, j]
            t1 = np.bincount(b, weights=(1 - ac) * rc, minlength=nb)
            t2 = np.bincount(b, weights=ac * rc, minlength=nb)
            with np.errstate(invalid="ignore", divide="ignore"):
                th1 = np.where(rank2, (s22 * t1 - s12 * t2) / det, t1 / s11)
                th2 = np.where(rank2, (s11 * t2 - s12 * t1) / det, 0.0)
            out[:, j] = rc - ((1 - ac) * th1[b] + ac * th2[b])
        return out

    # ------------------------------------------------------------ evaluation
    def _whiten(self, r: np.ndarray) -> np.ndarray:
        """Whiten point residuals (n,) or columns (n, m).

        Layout: the uncut points, then the cut points' within-interval parts
        (instrument noise only), then the whitened interval statistics.
        """
        two = r.ndim == 2
        rr = r if two else r[:, None]
        parts = []
        cut = self.cut
        if (~cut).any():
            parts.append(rr[~cut] / self.sigma)
        if self.nb:
            parts.append(self._within(rr) / self.sigma)
            st = self._stats(rr)
            parts.append(np.asarray(self.wbins @ st[self.seg_index]))
        out = np.concatenate(parts, axis=0)
        return out if two else out[:, 0]

    def _predict(self, p: Model) -> np.ndarray:
        from ._surface import surface_heights

        def run():
            return surface_heights(self.ctx.case, self.pts, p, self.ctx.trajectory(p))

        return self.ctx.memo(
            (p.key(self.predict_groups), "pts", id(self), self._points_gen), run)

    def predict_all(self, p: Model) -> np.ndarray:
        """Model heights at every point of the recording (m)."""
        from ._surface import surface_heights

        return surface_heights(self.ctx.case, self.pts_all, p, self.ctx.trajectory(p))

    def _line_cols(self, p: Model) -> list:
        """Whitened cos/sin pairs of the lines at the pass times (tool vibration)."""
        out = []
        for f0, _ in self.ctx.case.base_lines(p):
            c = np.zeros((self.z.size, 2))
            c[self.cut, 0] = np.cos(2 * np.pi * f0 * self.tpass[self.cut])
            c[self.cut, 1] = np.sin(2 * np.pi * f0 * self.tpass[self.cut])
            wc = self._whiten(c)
            wc = wc - self.q @ (self.q.T @ wc)
            out.append((wc[:, 0], wc[:, 1]))
        return out

    def residual(self, p: Model) -> np.ndarray:
        w = self._whiten(self.z - self._predict(p))
        w = w - self.q @ (self.q.T @ w)
        if self.ctx.case.base_lines(p):
            w = _remove_lines(
                w, self._line_cols(p), _line_amplitudes(self.ctx.case, p, "tool")
            )
        return _finite(w)

    def nuisance_fit(self, p: Model) -> np.ndarray:
        """Unwhitened residual with the fitted nuisance and lines removed (m).

        Piston, tilt, registration and the sinusoids of ``p``'s lines at the pass
        times are fitted by GLS and subtracted; kept points only.
        """
        r = self.z - self._predict(p)
        x = self.X_raw
        lines = self.ctx.case.base_lines(p)
        if lines:
            # the fitted sinusoids: the difference between the residual before and
            # after the known-amplitude line removal, mapped back by least squares
            cols = []
            for f0, _ in lines:
                for fn in (np.cos, np.sin):
                    c = np.zeros(self.z.size)
                    c[self.cut] = fn(2 * np.pi * f0 * self.tpass[self.cut])
                    cols.append(c)
            x = np.column_stack([x] + cols)
        coef, *_ = np.linalg.lstsq(self._whiten(x), self._whiten(r), rcond=None)
        return r - x @ coef


# ------------------------------------------------------------------------------
# Low-band nuisance (issue 19 item 5): content below the compared band
# ------------------------------------------------------------------------------
#: Eigenvalue (energy concentration in ``[-W, W]``) a Slepian sequence must reach
#: to enter the low-band basis: the well-concentrated ones (about ``2 N W - 1``).
SLEPIAN_CONCENTRATION = 0.9


def low_band_basis(n: int, fs: float, w: float) -> np.ndarray:
    """Orthonormal basis of the low-band nuisance of an ``n``-sample record.

    Columns: an offset, a linear trend, and the discrete prolate spheroidal
    (Slepian) sequences of half-bandwidth ``w`` whose energy concentration in
    ``[-w, w]`` is at least :data:`SLEPIAN_CONCENTRATION` (Slepian 1978; about
    ``2 n w / fs - 1`` of them, none for a record shorter than ``fs / w``),
    orthonormalised (thin QR). Projecting them out removes what a record holds
    below ``w`` -- the base vibration's PSD continuing below the compared band,
    offsets, drifts -- while removing from any bin above ``w`` at most its
    share ``1 - lambda`` of the sequences' energy.

    The Slepian sequences are the leading eigenvectors of the prolate matrix
    ``sin(2 pi w' (i - j)) / (pi (i - j))`` (``w' = w / fs``), found by subspace
    iteration from the Fourier vectors below ``w`` (Toeplitz products by FFT,
    ``O(n log n)``; LAPACK's tridiagonal route takes tens of seconds at 40 000
    samples) and a Rayleigh-Ritz step. Data and model are projected with the same
    basis, so the diagnosis does not depend on the iteration's last digits.
    Memoised on ``(n, fs, w)``.

    Parameters
    ----------
    n : int
        Record length in samples.
    fs : float
        Sampling rate in Hz.
    w : float
        Half-bandwidth in Hz (the diagnosis uses the compared band's lower
        edge, ``case.fs / 4096``).

    Returns
    -------
    ndarray of shape (n, m)
        Orthonormal columns (``Q.T @ Q = I``), dimensionless. Read-only.
    """
    return _low_band_basis(int(n), float(fs), float(w))


#: Subspace iterations of :func:`low_band_basis` from the Fourier start (the kept
#: span needs only to be separated from the poorly concentrated sequences).
SLEPIAN_ITERATIONS = 4


@_functools.lru_cache(maxsize=64)
def _low_band_basis(n: int, fs: float, w: float) -> np.ndarray:
    t = np.arange(n, dtype=float)
    cols = [np.ones(n), t - t.mean()] if n > 1 else [np.ones(n)]
    nw = n * w / fs
    if int(math.floor(2.0 * nw)) >= 1 and n > 2:
        wn = w / fs
        m = np.arange(1, n, dtype=float)
        col = np.concatenate([[2.0 * wn], np.sin(2 * np.pi * wn * m) / (np.pi * m)])
        # symmetric Toeplitz product by a circulant embedding of size 2n
        spec = np.fft.rfft(np.concatenate([col, [0.0], col[:0:-1]]))

        def prolate(y):
            return np.fft.irfft(spec[:, None] * np.fft.rfft(y, 2 * n, axis=0),
                                2 * n, axis=0)[:n]

        kk = np.arange(int(math.ceil(nw)) + 4)
        ph = 2 * np.pi * np.outer(t, kk) / n
        y = np.column_stack([np.cos(ph), np.sin(ph[:, 1:])])
        for _ in range(SLEPIAN_ITERATIONS):
            y = prolate(np.linalg.qr(y)[0])
        y = np.linalg.qr(y)[0]
        lam, v = np.linalg.eigh(y.T @ prolate(y))
        tapers = y @ v
        cols += [tapers[:, j] for j in range(lam.size)
                 if lam[j] >= SLEPIAN_CONCENTRATION]
    a = np.column_stack(cols)
    q, r = np.linalg.qr(a)
    keep = np.abs(np.diag(r)) > 1e-9 * max(1.0, float(np.abs(r[0, 0])))
    q = np.ascontiguousarray(q[:, keep])
    q.setflags(write=False)
    return q


def project_low_band(x: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """``x`` (last axis: samples) with the span of ``basis`` projected out."""
    x = np.asarray(x, dtype=float)
    return x - (x @ basis) @ basis.T


def projected_periodogram_expectation(
    r: np.ndarray, basis: np.ndarray, fs: float
) -> np.ndarray:
    """Expected one-sided periodogram of a projected stationary record.

    For a zero-mean record ``x`` of ``n`` samples with autocovariance ``r[tau]``
    (``tau = 0..n-1``, units^2) and ``y = (I - Q Q^T) x``, bin k of the
    rectangular-window periodogram ``2 |Y_k|^2 / (fs n)`` has the expectation
    ``2 / (fs n) a_k^H (I - P) R (I - P) a_k`` (``P = Q Q^T``, ``R`` the Toeplitz
    covariance, ``a_k = exp(2 pi i k t / n)``), computed exactly as
    ``a^H R a - 2 Re(a^H Q Q^T R a) + a^H Q (Q^T R Q) Q^T a`` with FFTs.

    Returns
    -------
    ndarray of shape (n // 2 + 1,)
        Expectation in units^2/Hz at bins ``k fs / n``.
    """
    from scipy.linalg import matmul_toeplitz

    r = np.asarray(r, dtype=float)
    n = r.size
    tau = np.arange(n)
    c = (n - tau) * r
    e0 = 2.0 * np.real(np.fft.fft(c)) - c[0]  # a^H R a
    if basis.shape[1]:
        rq = matmul_toeplitz(r, basis)
        if rq.ndim == 1:
            rq = rq[:, None]
        qh = np.fft.fft(basis, axis=0)  # a^H Q
        rqh = np.fft.fft(rq, axis=0)  # a^H R Q
        g = basis.T @ rq
        cross = np.real(np.sum(qh * np.conj(rqh), axis=1))
        quad = np.real(np.einsum("ki,ij,kj->k", qh, g, np.conj(qh)))
        e0 = e0 - 2.0 * cross + quad
    return e0[: n // 2 + 1] * 2.0 / (fs * n)


def sampled_autocov(
    case: CaseModel, p: Model, n: int, fs: float, output: str = "fe"
) -> np.ndarray:
    """Autocovariance (m^2, lags ``0..n-1``) of ``output``'s noise sampled at ``fs``
    (the model PSD on a grid :data:`LEAKAGE_OVERSAMPLING` times finer than the
    bins, as :func:`expected_periodogram`). A record at another rate than the
    controller's is taken as anti-aliased: the PSD up to the lower of the two
    Nyquist frequencies."""
    m = LEAKAGE_OVERSAMPLING * n
    fg = np.fft.rfftfreq(m, 1.0 / fs)
    sg = np.zeros(fg.shape)
    on = (fg > 0) & (fg <= 0.5 * case.fs)
    sg[on] = case.noise_psd(p, fg[on], output)
    return (fs * np.fft.irfft(0.5 * sg, m))[:n]


#: Time (s) at the start of a command or cut record sampled at another rate than
#: the controller's that is not compared: the record comes through an acquisition
#: anti-alias filter, which rings on the loop's start-up step (the loop starts
#: from rest with the command's first value, a step of micrometres) for about its
#: length; the diagnosis's model has no such filter. A 255-tap FIR at 199.6 kHz
#: rings for 0.64 ms, an 8-pole analogue filter at 40 kHz for tens of us.
RESAMPLED_SETTLE = 1e-3


def record_basis(case: CaseModel, n: int, fs: float, *, settle: bool = False
                 ) -> np.ndarray:
    """:func:`low_band_basis` of an ``n``-sample record at ``fs`` for ``case``
    (half-bandwidth: the compared band's lower edge).

    With ``settle`` (records with a command or a cut, which start from rest) at
    another rate than the controller's, the first :data:`RESAMPLED_SETTLE`
    seconds are nuisance too (one unit column per sample): data and model are
    compared after the acquisition filter settled.

    Notes
    -----
    The loop's free response from an unknown initial state (the noise's state at
    the record's first sample) was tried as a further nuisance and left out:
    its directions lie at 50-200 Hz, inside the compared band, where projecting
    them out makes the projected noise of those bins strongly correlated, which
    the per-bin whitening does not describe (a loop delay's cut-record
    signature was then refused on a blind case at 7 sigma).
    """
    w = analysis_band(fs, case)[0]
    if not settle:
        return low_band_basis(n, fs, w)
    m = 0
    if not same_rate(fs, case):
        m = min(int(math.ceil(RESAMPLED_SETTLE * fs)), n // 4)
    if m == 0:
        return low_band_basis(n, fs, w)
    key = (int(n), float(fs), float(w), m)
    cache = case.__dict__.setdefault("_record_bases", {})
    if key not in cache:
        head = np.zeros((n, m))
        head[np.arange(m), np.arange(m)] = 1.0
        cols = [head, low_band_basis(n, fs, w)]
        q, r = np.linalg.qr(np.column_stack(cols))
        keep = np.abs(np.diag(r)) > 1e-9
        q = np.ascontiguousarray(q[:, keep])
        q.setflags(write=False)
        if len(cache) > 16:
            cache.clear()
        cache[key] = q
    return cache[key]




def expected_projected_periodogram(
    case: CaseModel, p: Model, freq: np.ndarray, n: int, fs: float,
    basis: np.ndarray, output: str = "fe",
) -> np.ndarray:
    """:func:`expected_periodogram` of records with ``basis`` projected out
    (m^2/Hz at ``freq``, bins of the n-sample record). Records at another rate than
    the controller's are projected too (the projection takes most of the power of
    the bins next to the band edge): their autocovariance is the model PSD's up to
    the lower Nyquist frequency (:func:`sampled_autocov`)."""
    freq = np.asarray(freq, dtype=float)
    e = projected_periodogram_expectation(
        sampled_autocov(case, p, n, fs, output), basis, fs)
    return e[np.rint(freq * n / fs).astype(int)]


def _projected_whiten_weights(ctx, p, freq, n, fs, basis):
    """:func:`_whiten_weights` of records with ``basis`` projected out."""
    s = expected_projected_periodogram(ctx.case, p, freq, n, fs, basis)
    return 1.0 / np.sqrt(np.maximum(s, 1e-300) * n * fs / 4.0)


def _in_band_dof(basis: np.ndarray, keep: np.ndarray) -> int:
    """Degrees of freedom the projection takes from the compared bins ``keep``:
    the basis's energy there, ``sum_j 2 / n sum_{k in keep} |Q_jk|^2`` (real and
    imaginary parts; exact for white noise), rounded."""
    n = basis.shape[0]
    qh = np.fft.rfft(basis, axis=0)[keep]
    return int(round(2.0 / n * float(np.sum(np.abs(qh) ** 2))))
