"""The machine of the independent generator: numbers, plant, controller, FRFs.

Written from the machine file (read with :mod:`tomllib`) and the seed paper's
Eqs 1-7, without servosurf's servo code. SI units throughout (kg, N/m, N s/m, N/A,
A/V, V/m, Hz, s).

Plant (paper Fig. 5, Eqs 1-4, the network the machine file documents): the tool
m1 hangs on the coil carrier m2 through k1/c1; the flexure k2/c2 ties m2 to the X
carriage m3; k3/c3 tie the carriage to the base; the appendage m4 sits on m2 through
k4/c4; k5/c5 tie the coil to the magnets (base). The actuator force ``Kf I`` acts on
m2 (its reaction goes into the stiff ground), the cutting force on m1, the base
displacement ``xg`` enters through k3/c3 and k5/c5. Positions are relative to the
metrology frame that carries the sensor target and the work.

Amplifier (Eq 5) and sensor (Eq 7) are double poles ``w^2 / (s + w)^2`` whose -3 dB
frequency is the machine file's bandwidth, so ``w = 2 pi f_3dB / sqrt(sqrt(2) - 1)``
(``|w^2 / (j W + w)^2| = 1 / sqrt(2)`` gives ``1 + (W / w)^2 = sqrt(2)``).

Controller: the PIDF ``C(s) = Kp + Ki / s + Kd s / (Tf s + 1)`` discretised with
Tustin at the controller rate, applied through a zero-order hold after a computation
delay of ``delay`` samples. The gains are re-derived here from the tuning rule the
machine file documents (crossover ``bandwidth``, ``phase-margin``,
``Ki = rho Kp w_c``, ``Tf = 1 / (N w_c)``): ``|L(j w_c)| = 1`` and
``arg L(j w_c) = -180 deg + PM`` are two real equations linear in ``(Kp, Kd)``.
The tests compare the gains with ``servosurf.servo.tune_pidf``.

Effects that change the linear plant (an appended mass on a spring at the tool
holder, an extra delay, the small-signal stiffness and damping of a hysteretic or
frictional flexure) are arguments of :func:`plant_ss` and :func:`loop_frf`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]
MACHINE_FILE = REPO / "src" / "servosurf" / "data" / "machines" / "seed-prototype.toml"

#: -3 dB frequency of w^2 / (s + w)^2 relative to w.
DOUBLE_POLE_3DB = math.sqrt(math.sqrt(2.0) - 1.0)


@dataclass(frozen=True)
class PSD:
    """One-sided disturbance PSD ``(level^2 (f/fref)^slope + floor^2) /
    (1 + (f/corner)^order)`` in unit^2/Hz (level and floor in unit/sqrt(Hz))."""

    level: float
    fref: float = 1000.0
    slope: float = 0.0
    corner: float = math.inf
    order: float = 2.0
    floor: float = 0.0

    def __call__(self, f: np.ndarray) -> np.ndarray:
        """PSD at frequencies ``f`` (Hz, > 0), unit^2/Hz."""
        f = np.asarray(f, dtype=float)
        law = self.level**2 * np.power(f / self.fref, self.slope) + self.floor**2
        if math.isinf(self.corner):
            return law
        return law / (1.0 + np.power(f / self.corner, self.order))


@dataclass(frozen=True)
class Machine:
    """Every number of the machine file the generator uses (SI)."""

    m: tuple[float, float, float, float]
    k: tuple[float, float, float, float, float]
    c: tuple[float, float, float, float, float]
    kf: float  # N/A
    gi: float  # A/V
    f_amp: float  # Hz, -3 dB
    i_max: float  # A, rated current (reported only)
    sens: float  # V/m
    f_sens: float  # Hz, -3 dB
    sensor_dof: int  # 0: tool, 1: carrier
    fs: float  # Hz
    delay: float  # samples beyond the ZOH
    fc: float  # Hz crossover
    pm: float  # deg
    rho: float
    nratio: float
    psd: dict = field(default_factory=dict)

    @property
    def w_amp(self) -> float:
        """Amplifier double-pole corner, rad/s."""
        return 2 * math.pi * self.f_amp / DOUBLE_POLE_3DB

    @property
    def w_sens(self) -> float:
        """Sensor double-pole corner, rad/s."""
        return 2 * math.pi * self.f_sens / DOUBLE_POLE_3DB

    @property
    def moving_mass(self) -> float:
        """m1 + m2 in kg."""
        return self.m[0] + self.m[1]


def _psd(tab: dict) -> PSD:
    return PSD(
        level=float(tab.get("level", 0.0)),
        fref=float(tab.get("ref-frequency", 1000.0)),
        slope=float(tab.get("slope", 0.0)),
        corner=float(tab.get("corner", math.inf)),
        order=float(tab.get("order", 2.0)),
        floor=float(tab.get("floor", 0.0)),
    )


def load_machine(
    path: str | Path = MACHINE_FILE, *, moving_mass: float = 0.175,
    bandwidth: float = 468.0,
) -> Machine:
    """Read the machine TOML and set the moving mass and crossover.

    Parameters
    ----------
    path : str or Path
        Machine file (the seed prototype by default).
    moving_mass : float, default: 0.175
        m1 + m2 in kg; the difference goes to ``mechanics.added-mass-on``.
    bandwidth : float, default: 468.0
        Open-loop crossover in Hz.

    Returns
    -------
    Machine
    """
    with open(path, "rb") as fh:
        d = tomllib.load(fh)
    mech = d["mechanics"]
    m = [float(mech[f"m{i}"]) for i in range(1, 5)]
    target = {"m1": 0, "m2": 1}[str(mech.get("added-mass-on", "m2"))]
    m[target] += moving_mass - (m[0] + m[1])
    act, sen, con = d["actuator"], d["sensor"], d["controller"]
    dist = d["disturbances"]
    return Machine(
        m=tuple(m),
        k=tuple(float(mech[f"k{i}"]) for i in range(1, 6)),
        c=tuple(float(mech[f"c{i}"]) for i in range(1, 6)),
        kf=float(act["force-constant"]),
        gi=float(act["current-gain"]),
        f_amp=float(act["current-bandwidth"]),
        i_max=float(act.get("max-current", math.inf)),
        sens=float(sen["sensitivity"]),
        f_sens=float(sen["bandwidth"]),
        sensor_dof=1 if sen.get("location", "carrier") == "carrier" else 0,
        fs=float(con["sample-rate"]),
        delay=float(con["delay"]),
        fc=float(bandwidth),
        pm=float(con["phase-margin"]),
        rho=float(con["integral-ratio"]),
        nratio=float(con["derivative-filter-ratio"]),
        psd={
            "sensor": _psd(dist["sensor-noise"]),
            "current": _psd(dist["current-noise"]),
            "base": _psd(dist["base-vibration"]),
        },
    )


# ------------------------------------------------------------------ linear extras
@dataclass(frozen=True)
class LinearExtras:
    """Changes of the linear plant made by an effect (all default: none).

    Attributes
    ----------
    mode_mass, mode_k, mode_c : float
        A mass (kg) on a spring (N/m) and damper (N s/m) attached to the tool m1.
    extra_delay : float
        Loop delay added to the machine's, s.
    flex_k, flex_c : float
        Extra stiffness (N/m) and damping (N s/m) between carrier m2 and carriage
        m3 (small-signal equivalent of a hysteretic or frictional flexure).
    kf_scale : float
        Force constant at the rest position relative to the machine's.
    """

    mode_mass: float = 0.0
    mode_k: float = 0.0
    mode_c: float = 0.0
    extra_delay: float = 0.0
    flex_k: float = 0.0
    flex_c: float = 0.0
    kf_scale: float = 1.0


def mechanics(mach: Machine, ex: LinearExtras = LinearExtras()):
    """Mass, stiffness and damping matrices and the input vectors of the network.

    Returns
    -------
    M, K, C : ndarray of shape (n, n)
        n = 4 DOFs (x1 tool, x2 carrier, x3 carriage, x4 appendage), 5 with the
        appended mass (x5).
    b_act, b_tool : ndarray of shape (n,)
        Where the actuator force (m2) and the cutting force (m1) act.
    kg, cg : ndarray of shape (n,)
        Force per metre and per metre/second of base motion.
    """
    n = 5 if ex.mode_mass > 0 else 4
    M = np.zeros((n, n))
    K = np.zeros((n, n))
    C = np.zeros((n, n))
    kg = np.zeros(n)
    cg = np.zeros(n)
    masses = list(mach.m) + ([ex.mode_mass] if n == 5 else [])
    for i, mi in enumerate(masses):
        M[i, i] = mi
    k1, k2, k3, k4, k5 = mach.k
    c1, c2, c3, c4, c5 = mach.c
    # springs between two masses: force on i is k (x_j - x_i)
    pairs = [(0, 1, k1, c1), (1, 2, k2 + ex.flex_k, c2 + ex.flex_c), (1, 3, k4, c4)]
    if n == 5:
        pairs.append((0, 4, ex.mode_k, ex.mode_c))
    for i, j, kk, cc in pairs:
        for a, b in ((i, j), (j, i)):
            K[a, a] += kk
            K[a, b] -= kk
            C[a, a] += cc
            C[a, b] -= cc
    # springs to the base: force on i is k (xg - x_i)
    for i, kk, cc in ((2, k3, c3), (1, k5, c5)):
        K[i, i] += kk
        C[i, i] += cc
        kg[i] += kk
        cg[i] += cc
    b_act = np.zeros(n)
    b_act[1] = 1.0
    b_tool = np.zeros(n)
    b_tool[0] = 1.0
    return M, K, C, b_act, b_tool, kg, cg


#: Inputs of :func:`plant_ss`.
INPUTS = ("u", "current_noise", "force", "base_x", "base_v")
#: Outputs of :func:`plant_ss`.
OUTPUTS = ("tool", "meas_dof", "sensor")


def plant_ss(mach: Machine, ex: LinearExtras = LinearExtras()):
    """Continuous state space of amplifier + mechanics + sensor filter.

    States ``[x (n), v (n), I, dI/dt, y, dy/dt]``; inputs :data:`INPUTS` (DAC
    voltage V after hold and delay, current noise A, force on the tool N, base
    displacement m and base velocity m/s); outputs :data:`OUTPUTS` (tool x1 m, the
    sensed DOF m, sensor-filtered position y m).

    Returns
    -------
    A : ndarray of shape (ns, ns)
    B : ndarray of shape (ns, 5)
    C : ndarray of shape (3, ns)
    """
    M, K, Cm, b_act, b_tool, kg, cg = mechanics(mach, ex)
    n = M.shape[0]
    ns = 2 * n + 4
    minv = np.linalg.inv(M)
    A = np.zeros((ns, ns))
    B = np.zeros((ns, 5))
    A[:n, n : 2 * n] = np.eye(n)
    A[n : 2 * n, :n] = -minv @ K
    A[n : 2 * n, n : 2 * n] = -minv @ Cm
    ia = 2 * n
    kf = mach.kf * ex.kf_scale
    A[n : 2 * n, ia] = minv @ b_act * kf
    wa = mach.w_amp
    A[ia, ia + 1] = 1.0
    A[ia + 1, ia] = -(wa**2)
    A[ia + 1, ia + 1] = -2 * wa
    B[ia + 1, 0] = wa**2 * mach.gi
    B[n : 2 * n, 1] = minv @ b_act * kf
    B[n : 2 * n, 2] = minv @ b_tool
    B[n : 2 * n, 3] = minv @ kg
    B[n : 2 * n, 4] = minv @ cg
    iy = ia + 2
    ws = mach.w_sens
    A[iy, iy + 1] = 1.0
    A[iy + 1, iy] = -(ws**2)
    A[iy + 1, iy + 1] = -2 * ws
    A[iy + 1, mach.sensor_dof] += ws**2
    C = np.zeros((3, ns))
    C[0, 0] = 1.0
    C[1, mach.sensor_dof] = 1.0
    C[2, iy] = 1.0
    return A, B, C


def plant_frf(mach: Machine, freq: np.ndarray, ex: LinearExtras = LinearExtras(),
              flex_dyn: np.ndarray | None = None):
    """Open-loop plant responses ``C (sI - A)^-1 B`` at ``freq`` (Hz).

    ``flex_dyn`` (complex N/m per frequency, optional) is an extra dynamic
    stiffness between carrier and carriage (a nonlinear flexure term's describing
    function at the FRF excitation amplitude).

    Returns
    -------
    dict
        ``h[(input, output)]`` complex arrays; the base input ``"base"`` combines
        displacement and velocity (per metre of base displacement).
    """
    A, B, C = plant_ss(mach, ex)
    s = 2j * np.pi * np.asarray(freq, dtype=float)
    ns = A.shape[0]
    eye = np.eye(ns)
    lhs = s[:, None, None] * eye[None] - A[None]
    if flex_dyn is not None:
        M, *_ = mechanics(mach, ex)
        n = M.shape[0]
        kd = np.broadcast_to(np.asarray(flex_dyn, dtype=complex), s.shape)
        for row, sign in ((1, 1.0), (2, -1.0)):  # v2 and v3 equations
            mi = M[row, row]
            lhs[:, n + row, 1] += sign * kd / mi
            lhs[:, n + row, 2] -= sign * kd / mi
    x = np.linalg.solve(lhs, np.broadcast_to(B, (s.size,) + B.shape))
    h = np.einsum("oi,fij->foj", C, x)  # (nf, outputs, inputs)
    out = {}
    for j, name in enumerate(INPUTS[:3]):
        for o, oname in enumerate(OUTPUTS):
            out[(name, oname)] = h[:, o, j]
    for o, oname in enumerate(OUTPUTS):
        out[("base", oname)] = h[:, o, 3] + s * h[:, o, 4]
    return out


# ------------------------------------------------------------------ controller
@dataclass(frozen=True)
class Controller:
    """PIDF gains (V/V, V/(V s), V s/V, s) at the sample rate ``fs`` (Hz)."""

    kp: float
    ki: float
    kd: float
    tf: float
    fs: float

    def frf(self, freq: np.ndarray, *, discrete: bool = True) -> np.ndarray:
        """Controller response at ``freq`` (Hz): Tustin in z, or continuous."""
        w = 2 * np.pi * np.asarray(freq, dtype=float)
        if not discrete:
            s = 1j * w
            return self.kp + self.ki / s + self.kd * s / (self.tf * s + 1.0)
        T = 1.0 / self.fs
        z = np.exp(1j * w * T)
        integ = 0.5 * T * (z + 1.0) / (z - 1.0)
        deriv = 2.0 * (z - 1.0) / ((2 * self.tf + T) * z - (2 * self.tf - T))
        return self.kp + self.ki * integ + self.kd * deriv


def hold_and_delay(mach: Machine, freq: np.ndarray, extra_delay: float = 0.0):
    """ZOH factor times the computation (and extra) delay at ``freq`` (Hz)."""
    s = 2j * np.pi * np.asarray(freq, dtype=float)
    T = 1.0 / mach.fs
    zoh = (1.0 - np.exp(-s * T)) / (s * T)
    return zoh * np.exp(-s * (mach.delay * T + extra_delay))


def tune(mach: Machine) -> Controller:
    """Re-derive the PIDF gains from the machine's tuning rule (see module doc)."""
    wc = 2 * math.pi * mach.fc
    f = np.array([mach.fc])
    tf = 1.0 / (mach.nratio * wc)
    h = plant_frf(mach, f)
    g = (hold_and_delay(mach, f) * h[("u", "sensor")] * mach.sens)[0]
    T = 1.0 / mach.fs
    z = np.exp(1j * wc * T)
    a_term = 1.0 + mach.rho * wc * 0.5 * T * (z + 1.0) / (z - 1.0)
    b_term = 2.0 * (z - 1.0) / ((2 * tf + T) * z - (2 * tf - T))
    target = -np.exp(1j * math.radians(mach.pm)) / g
    mat = np.array([[a_term.real, b_term.real], [a_term.imag, b_term.imag]])
    kp, kd = np.linalg.solve(mat, np.array([target.real, target.imag]))
    return Controller(float(kp), float(kp * mach.rho * wc), float(kd), tf, mach.fs)


# ------------------------------------------------------------------ closed loop
def loop_frf(
    mach: Machine,
    ctrl: Controller,
    freq: np.ndarray,
    ex: LinearExtras = LinearExtras(),
    *,
    discrete: bool = True,
    flex_dyn: np.ndarray | None = None,
) -> dict:
    """Open- and closed-loop responses of the linear(ised) loop at ``freq`` (Hz).

    Sampled-data approximation with ``discrete``: the Tustin controller at
    ``exp(j w T)``, the ZOH factor and the delay on the continuous plant (aliasing
    of the plant's response above Nyquist neglected). ``discrete=False``: the
    continuous controller, no hold, no delay.

    Returns
    -------
    dict
        ``"loop"`` (L), ``"open_loop"`` (DAC V -> sensor V, with hold and delay),
        and ``(input, output)`` for inputs ``reference``, ``sensor_noise`` (m),
        ``current_noise`` (A), ``force`` (N), ``base`` (m) and outputs ``tool``
        (x1, m), ``sensor`` (measured position, m), ``fe`` (following error
        ``r - measured``, m).
    """
    freq = np.asarray(freq, dtype=float)
    h = plant_frf(mach, freq, ex, flex_dyn)
    if discrete:
        d = hold_and_delay(mach, freq, ex.extra_delay)
    else:
        d = np.ones(freq.size, dtype=complex)
    k = ctrl.frf(freq, discrete=discrete) * mach.sens * d  # V at the amp per m
    gy = h[("u", "sensor")]
    g1 = h[("u", "tool")]
    loop = k * gy
    one = 1.0 + loop
    out = {"loop": loop, "open_loop": d * gy * mach.sens}
    # reference r and sensor noise n: the error is r - n - y
    for name, sign in (("reference", 1.0), ("sensor_noise", -1.0)):
        y = sign * loop / one
        out[(name, "sensor")] = y if name == "reference" else 1.0 + y
        out[(name, "fe")] = sign / one
        out[(name, "tool")] = g1 * k * sign / one
    for name in ("current_noise", "force", "base"):
        hy = h[(name, "sensor")]
        h1 = h[(name, "tool")]
        y = hy / one
        out[(name, "sensor")] = y
        out[(name, "fe")] = -y
        out[(name, "tool")] = h1 - g1 * k * y
    return out


def appended_mode(mach: Machine, ex: LinearExtras) -> tuple[float, float]:
    """Natural frequency (Hz) and damping ratio of the appended-mass mode.

    The eigenvalue of the mechanics (with the appended mass) whose eigenvector has
    the largest share of kinetic energy in the appended mass.
    """
    M, K, C, *_ = mechanics(mach, ex)
    n = M.shape[0]
    minv = np.linalg.inv(M)
    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.eye(n)
    a[n:, :n] = -minv @ K
    a[n:, n:] = -minv @ C
    lam, vec = np.linalg.eig(a)
    best, share = None, -1.0
    for i in range(lam.size):
        if lam[i].imag <= 0:
            continue
        v = vec[:n, i]
        e = np.abs(v) ** 2 * np.diag(M)
        sh = e[-1] / e.sum()
        if sh > share:
            best, share = lam[i], sh
    wn = abs(best)
    return float(wn / (2 * math.pi)), float(-best.real / wn)

