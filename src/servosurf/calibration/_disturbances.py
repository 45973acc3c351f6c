"""Disturbance PSD calibration: shape grid, level fits, and the search for one set.

The paper's measured PSDs (Table 1, Fig. 8) are not published. servosurf models them
with one family (:class:`Shape` and three levels):

* sensor noise (position equivalent, rolled off by the sensor's 15 kHz bandwidth),
  ``Ws = (a_s^2 (f / 1 kHz)^p_s + (r_s a_s)^2) / (1 + (f / 15 kHz)^4)`` m^2/Hz;
* current noise ``Wi = a_i^2 (f / 1 kHz)^p_i / (1 + (f / 400 kHz)^2)`` A^2/Hz;
* base displacement ``Wg = a_g^2 (f / 1 kHz)^p_g`` m^2/Hz.

The shape ``(p_s, r_s, p_i, p_g)`` is chosen from a grid of round values
(:data:`SHAPE_GRID`); the three levels ``(a_s, a_i, a_g)`` are fitted. A *candidate*
is a shape with levels fitted to one subset of the paper's figures
(:data:`SUBSETS`); every candidate is then evaluated against every figure, and the
search reports which figures no candidate satisfies together.

The two readings of section 3.3's "468 Hz" are searched apart: ``"crossover"``
(servosurf's convention, section 4.1) and ``"-3dB"`` (section 3.3's own words: "The
closed loop bandwidth (-3dB) is kept the same at 468 Hz").
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import scipy as sp

from ..servo._machine import Disturbances, Machine, PSDModel
from ._bank import ErrorBank, bandwidth_for_3db, curve_minimum
from ._figures import FIGURES, PaperFigure, within

__all__ = [
    "Shape",
    "SHAPE_GRID",
    "SUBSETS",
    "READINGS",
    "DisturbanceFit",
    "DisturbanceSearch",
    "make_bank",
    "shape_psd",
    "to_disturbances",
    "shape_of",
    "bank_figures",
    "fit_levels",
    "search_disturbances",
    "DISTURBANCE_FIGURES",
]

#: Readings of section 3.3's "468 Hz".
READINGS = ("crossover", "-3dB")

#: Figures a disturbance calibration changes (keys of FIGURES).
DISTURBANCE_FIGURES = (
    "optimum_following_0075",
    "optimum_following_0175",
    "following_rms_468",
    "real_rms_468_s52",
    "sensor_noise_rms",
    "real_rms_0075_s33",
    "real_rms_0175_s33",
    "optimum_real_0075",
    "optimum_real_0175",
    "claim_mass_above_900",
    "claim_following_same_level",
    "claim_following_lower_with_mass",
    "claim_optimum_lower_with_mass",
    "claim_sensor_share_above_1k",
    "claim_base_share_small",
    "claim_current_dominates_301",
)

_S52 = (
    "optimum_following_0075",
    "optimum_following_0175",
    "following_rms_468",
    "real_rms_468_s52",
)
_S33 = (
    "real_rms_0075_s33",
    "real_rms_0175_s33",
    "optimum_real_0075",
    "optimum_real_0175",
)
_QUANT = _S52 + ("sensor_noise_rms",) + _S33

#: Subsets of figures the levels are fitted to. Every fit also keeps the sensor noise
#: inside the CPL190 band (``sensor_noise_rms``): the search is physically bounded.
SUBSETS: dict[str, tuple[str, ...]] = {
    "section-5.2": _S52,
    "section-3.3": _S33,
    "measured": (
        "optimum_following_0075",
        "optimum_following_0175",
        "following_rms_468",
    ),
    "all": _S52 + _S33,
    **{f"all-but-{k}": tuple(x for x in _S52 + _S33 if x != k) for k in _S52 + _S33},
}

#: Main subsets of the search (the leave-one-out subsets run on the best shapes).
MAIN_SUBSETS = ("section-5.2", "section-3.3", "measured", "all")

#: Reference frequency of the levels, Hz.
REF_FREQUENCY = 1000.0
#: Sensor noise roll-off: the CPL190's 15 kHz bandwidth, order 4 (a double pole).
SENSOR_CORNER, SENSOR_ORDER = 15e3, 4.0
#: Current noise roll-off: the 400 kHz current loop, order 2.
CURRENT_CORNER, CURRENT_ORDER = 400e3, 2.0


@dataclass(frozen=True, order=True)
class Shape:
    """Exponents of the disturbance PSD family (see the module docstring).

    Attributes
    ----------
    sensor_slope : float
        ``p_s``, exponent of the sensor-noise power law.
    sensor_floor_ratio : float
        ``r_s``, white sensor floor (ASD) over the power law's ASD at 1 kHz.
    current_slope : float
        ``p_i``, exponent of the current-noise power law.
    base_slope : float
        ``p_g``, exponent of the base-displacement power law (-4: white acceleration;
        -2: white velocity).
    """

    sensor_slope: float
    sensor_floor_ratio: float
    current_slope: float
    base_slope: float

    @property
    def simplicity(self) -> tuple:
        """Sort key: fewer non-zero exponents and smaller ones first."""
        nz = sum(
            1 for v in (self.sensor_slope, self.sensor_floor_ratio, self.current_slope)
            if v != 0
        ) + (self.base_slope != -4.0)
        size = abs(self.sensor_slope) + self.sensor_floor_ratio + abs(
            self.current_slope) + abs(self.base_slope + 4.0)
        return (nz, size, self)

    def as_dict(self) -> dict:
        """Plain dictionary."""
        return {
            "sensor_slope": self.sensor_slope,
            "sensor_floor_ratio": self.sensor_floor_ratio,
            "current_slope": self.current_slope,
            "base_slope": self.base_slope,
        }


#: The searched shapes: round exponents over the range the paper's qualitative
#: statements allow (white to pink or blue sensor noise, with or without a floor).
SHAPE_GRID: tuple[Shape, ...] = tuple(
    Shape(*s)
    for s in itertools.product(
        (-1.0, -0.5, 0.0, 0.5, 1.0),
        (0.0, 1.0, 2.0),
        (-1.0, 0.0, 0.5, 1.0, 1.5),
        (-4.0, -2.0),
    )
)


def shape_psd(shape: Shape, levels, freq: np.ndarray) -> np.ndarray:
    """Disturbance PSDs of a shape and levels, shape (3, nf), SI units per source.

    ``levels`` are the ASDs at 1 kHz: sensor (m/sqrt(Hz)), current (A/sqrt(Hz)),
    base (m/sqrt(Hz)).
    """
    a_s, a_i, a_g = (float(x) for x in levels)
    f = np.asarray(freq, dtype=float) / REF_FREQUENCY
    ws = a_s**2 * (f**shape.sensor_slope + shape.sensor_floor_ratio**2)
    ws = ws / (1.0 + (f * REF_FREQUENCY / SENSOR_CORNER) ** SENSOR_ORDER)
    wi = a_i**2 * f**shape.current_slope
    wi = wi / (1.0 + (f * REF_FREQUENCY / CURRENT_CORNER) ** CURRENT_ORDER)
    wg = a_g**2 * f**shape.base_slope
    return np.array([ws, wi, wg])


def to_disturbances(shape: Shape, levels, *, name: str, source: str) -> Disturbances:
    """The machine-file form of a shape and its levels (see :func:`shape_psd`)."""
    a_s, a_i, a_g = (float(x) for x in levels)
    return Disturbances(
        name=name,
        source=source,
        sensor_noise=PSDModel(
            level=a_s,
            ref_frequency=REF_FREQUENCY,
            slope=shape.sensor_slope,
            corner=SENSOR_CORNER,
            order=SENSOR_ORDER,
            floor=a_s * shape.sensor_floor_ratio,
        ),
        current_noise=PSDModel(
            level=a_i,
            ref_frequency=REF_FREQUENCY,
            slope=shape.current_slope,
            corner=CURRENT_CORNER,
            order=CURRENT_ORDER,
        ),
        base_vibration=PSDModel(
            level=a_g, ref_frequency=REF_FREQUENCY, slope=shape.base_slope
        ),
    )


def shape_of(d: Disturbances) -> tuple[Shape, tuple[float, float, float]]:
    """Shape and levels of a machine-file disturbance set of this family.

    Raises
    ------
    ValueError
        When the set is not of the family (other corners, a CSV file, ...).
    """
    s, i, g = d.sensor_noise, d.current_noise, d.base_vibration
    ok = (
        not (s.csv or i.csv or g.csv)
        and s.ref_frequency == i.ref_frequency == g.ref_frequency == REF_FREQUENCY
        and (s.corner, s.order) == (SENSOR_CORNER, SENSOR_ORDER)
        and (i.corner, i.order) == (CURRENT_CORNER, CURRENT_ORDER)
        and i.floor == 0.0
        and g.floor == 0.0
        and g.corner >= 1e9
        and s.level > 0
    )
    if not ok:
        raise ValueError(f"disturbances {d.name!r} are not of the calibrated family")
    shape = Shape(s.slope, s.floor / s.level, i.slope, g.slope)
    return shape, (s.level, i.level, g.level)


# ----------------------------------------------------------------------- figures
@dataclass(eq=False)
class _Context:
    """A bank with the bandwidth indices the figures need."""

    bank: ErrorBank
    crossover_for_3db: tuple[float, float]
    _index: dict = field(default_factory=dict)

    def j(self, bandwidth: float) -> int:
        if bandwidth not in self._index:
            self._index[bandwidth] = self.bank.index(bandwidth)
        return self._index[bandwidth]


def make_bank(machine: Machine, *, n_bandwidths: int = 72, n_freq: int = 2000):
    """The error bank for the disturbance figures (masses 0.075 and 0.175 kg).

    Bandwidths: ``n_bandwidths`` log-spaced from 150 Hz to 1.9 kHz plus the
    bandwidths the paper names (301, 468, 1000, 1448, 1500 Hz) and the crossovers
    whose closed-loop -3 dB bandwidth is 468 Hz (section 3.3's reading).
    """
    from ..noise._psd import frequency_grid

    x3 = tuple(
        bandwidth_for_3db(machine.with_moving_mass(m), 468.0) for m in (0.075, 0.175)
    )
    named = [301.0, 468.0, 900.0, 1000.0, 1448.0, 1500.0, *x3]
    bws = np.unique(np.concatenate([np.geomspace(150.0, 1900.0, n_bandwidths), named]))
    freq = frequency_grid(machine.controller.sample_rate, n=n_freq)
    return _Context(ErrorBank(machine, (0.075, 0.175), bws, freq=freq), x3)


@dataclass(frozen=True, eq=False)
class _Basis:
    """Error powers of one shape at unit levels (the fits only rescale them)."""

    powers: np.ndarray  # (3 src, m, b, out) m^2 per unit level^2
    sensor_power: float  # sensor-noise variance at unit level, m^2
    band_301: np.ndarray  # (3,) following-error power below 301 Hz at 301 Hz, 0.175 kg


def _basis(ctx: _Context, shape: Shape) -> _Basis:
    bank = ctx.bank
    unit = shape_psd(shape, (1.0, 1.0, 1.0), bank.freq)
    p = np.moveaxis(bank.powers(unit), 2, 0)  # (src, m, b, out)
    lo = bank.freq <= 301.0
    j301 = ctx.j(301.0)
    b301 = np.sum(bank.h[1, j301, :, 1][:, lo] * unit[:, lo], axis=1)
    return _Basis(p, float(np.sum(bank.weights * unit[0])), b301)


def bank_figures(
    ctx: _Context, psd: np.ndarray | None = None, *, reading: str,
    basis: _Basis | None = None, levels=None, claims: bool = True,
) -> dict[str, float]:
    """Values of :data:`DISTURBANCE_FIGURES` for one disturbance PSD set.

    Parameters
    ----------
    ctx : object
        From :func:`make_bank`.
    psd : ndarray of shape (3, nf), optional
        The disturbance PSDs on the bank's frequencies (or give ``basis`` and
        ``levels``: a shape's unit-level powers and the three levels).
    reading : {"crossover", "-3dB"}
        Reading of section 3.3's 468 Hz.
    claims : bool, default: True
        Also evaluate the qualitative claims (the level fits skip them).

    Returns
    -------
    dict
        Figure key -> value (SI; ratios and shares dimensionless).
    """
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    bank = ctx.bank
    if psd is not None:
        p = np.moveaxis(bank.powers(psd), 2, 0)
        lo = bank.freq <= 301.0
        j301 = ctx.j(301.0)
        b301 = np.sum(bank.h[1, j301, :, 1][:, lo] * psd[:, lo], axis=1)
        sensor = float(np.sum(bank.weights * psd[0]))
    else:
        sq = np.asarray(levels, dtype=float) ** 2
        p = basis.powers * sq[:, None, None, None]
        b301 = basis.band_301 * sq
        sensor = basis.sensor_power * sq[0]
    real, fol = p[..., 0].sum(0), p[..., 1].sum(0)  # (m, b)
    bws = bank.bandwidths
    j468 = ctx.j(468.0)
    out: dict[str, float] = {}
    out["optimum_following_0075"] = curve_minimum(bws, np.sqrt(fol[0]))
    out["optimum_following_0175"] = curve_minimum(bws, np.sqrt(fol[1]))
    out["optimum_real_0075"] = curve_minimum(bws, np.sqrt(real[0]))
    out["optimum_real_0175"] = curve_minimum(bws, np.sqrt(real[1]))
    out["following_rms_468"] = float(np.sqrt(fol[1, j468]))
    out["real_rms_468_s52"] = float(np.sqrt(real[1, j468]))
    if reading == "crossover":
        j0 = j1 = j468
    else:
        j0, j1 = ctx.j(ctx.crossover_for_3db[0]), ctx.j(ctx.crossover_for_3db[1])
    out["real_rms_0075_s33"] = float(np.sqrt(real[0, j0]))
    out["real_rms_0175_s33"] = float(np.sqrt(real[1, j1]))
    out["sensor_noise_rms"] = float(np.sqrt(sensor))
    if not claims:
        return out
    with np.errstate(invalid="ignore", divide="ignore"):
        both = bank.ok[0] & bank.ok[1]
        sel = both & (bws >= 900.0) & (bws <= 1500.0)
        out["claim_mass_above_900"] = _max(
            np.abs(np.sqrt(real[1, sel] / real[0, sel]) - 1)
        )
        sel = both & (bws >= 1000.0) & (bws <= 1500.0)
        out["claim_following_same_level"] = _max(
            np.abs(np.sqrt(fol[1, sel] / fol[0, sel]) - 1)
        )
        sel = both & (bws < 1000.0)
        out["claim_following_lower_with_mass"] = _max(
            np.sqrt(fol[1, sel] / fol[0, sel])
        )
        out["claim_optimum_lower_with_mass"] = (
            out["optimum_real_0175"] / out["optimum_real_0075"]
        )
        sel = bank.ok[1] & (bws >= 1000.0)
        share = p[0, 1, :, 0] / real[1]
        out["claim_sensor_share_above_1k"] = (
            float(np.min(share[sel])) if sel.any() else math.nan
        )
        out["claim_base_share_small"] = _max((p[2, 1, :, 0] / real[1])[bank.ok[1]])
        out["claim_current_dominates_301"] = float(b301[1] / b301[0])
    return out


def _max(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else math.nan


def residual(fig: PaperFigure, value: float) -> float:
    """Signed distance of ``value`` from the figure, in units of its tolerance.

    Quantitative figures: the log ratio to the paper's value divided by the log of
    the tolerance factor (``|r| <= 1`` is within); bands and claims: zero inside,
    the distance outside. Used as a least-squares residual by the level fits.
    """
    v = float(value)
    if not math.isfinite(v) or (fig.test in ("rel", "ratio", "band") and v <= 0):
        return 20.0
    if fig.test == "rel":
        return math.log(v / fig.value) / math.log(1.0 + fig.tol)
    if fig.test == "ratio":
        return math.log(v / fig.value) / math.log(fig.tol)
    if fig.test == "band":
        lo, hi = fig.band
        scale = math.log(1.0 + 0.10)
        if v < lo:
            return math.log(v / lo) / scale
        if v > hi:
            return math.log(v / hi) / scale
        return 0.0
    if fig.test == "max":
        return max(0.0, (v - fig.tol) / max(abs(fig.tol), 0.1))
    if fig.test == "min":
        return min(0.0, (v - fig.tol) / max(abs(fig.tol), 0.1))
    raise ValueError(fig.test)


# ---------------------------------------------------------------------- fitting
@dataclass(frozen=True, eq=False)
class DisturbanceFit:
    """Levels of one shape fitted to a subset of the paper's figures.

    Attributes
    ----------
    shape : Shape
        The PSD exponents.
    levels : tuple of float
        ASDs at 1 kHz: sensor (m/sqrt(Hz)), current (A/sqrt(Hz)), base (m/sqrt(Hz)).
    subset : str
        Name in :data:`SUBSETS` of the figures the levels were fitted to.
    reading : str
        Reading of section 3.3's 468 Hz.
    figures : dict
        Value of every figure of :data:`DISTURBANCE_FIGURES` (SI).
    cost : float
        Sum of squared residuals over the fitted subset and the sensor band.
    """

    shape: Shape
    levels: tuple[float, float, float]
    subset: str
    reading: str
    figures: dict = field(repr=False)
    cost: float = 0.0

    @property
    def targets(self) -> tuple[str, ...]:
        """Figure keys the levels were fitted to (with the physical bound)."""
        return SUBSETS[self.subset] + ("sensor_noise_rms",)

    def violated(self, keys=DISTURBANCE_FIGURES) -> list[str]:
        """Keys of the figures outside their tolerance."""
        return [k for k in keys if not within(FIGURES[k], self.figures[k])]

    def score(self) -> tuple:
        """Selection key: violated measured figures, then model figures, then claims
        resting on the paper's model, then the summed squared residuals."""
        bad = self.violated()
        meas = sum(1 for k in bad if FIGURES[k].basis == "measured")
        quant_model = sum(
            1 for k in bad if FIGURES[k].basis == "model" and FIGURES[k].kind != "claim"
        )
        claims = sum(
            1 for k in bad if FIGURES[k].kind == "claim" and FIGURES[k].basis == "model"
        )
        total = sum(
            residual(FIGURES[k], self.figures[k]) ** 2 for k in DISTURBANCE_FIGURES
        )
        return (meas, quant_model, claims, round(total, 6), self.shape.simplicity)

    def to_disturbances(self, *, name: str, source: str) -> Disturbances:
        """The machine-file form of this fit."""
        return to_disturbances(self.shape, self.levels, name=name, source=source)


#: Starting levels of the fits (ASD at 1 kHz): several, for a global search.
_STARTS = (
    (3e-12, 3e-7, 3e-13),
    (1e-12, 1e-6, 1e-13),
    (6e-12, 1e-7, 1e-12),
)
_BOUNDS = ((1e-15, 1e-11, 1e-17), (1e-9, 1e-3, 1e-9))
#: A fitted level within this many decades of its lower bound is set to the bound.
LOWER_BOUND_SNAP = 0.01


def fit_levels(
    ctx: _Context,
    shape: Shape,
    subset: str,
    *,
    reading: str = "crossover",
    basis: _Basis | None = None,
) -> DisturbanceFit:
    """Fit the three levels of ``shape`` to the figures of ``subset``.

    Least squares on :func:`residual` (log ratios in tolerance units) from three
    fixed starting points; the sensor noise is kept in its CPL190 band by a hinge
    residual. Deterministic.
    """
    keys = SUBSETS[subset] + ("sensor_noise_rms",)
    figs = [FIGURES[k] for k in keys]
    basis = basis if basis is not None else _basis(ctx, shape)

    def res(x: np.ndarray) -> np.ndarray:
        vals = bank_figures(
            ctx, reading=reading, basis=basis, levels=10.0**x, claims=False
        )
        return np.array([residual(g, vals[g.key]) for g in figs])

    best = None
    lo, hi = (np.log10(b) for b in _BOUNDS)
    for start in _STARTS:
        if best is not None and best.cost < 1e-10:
            break  # an exact fit: the later starts cannot improve it
        r = sp.optimize.least_squares(
            res,
            np.log10(start),
            bounds=(lo, hi),
            diff_step=1e-5,
            x_scale=0.3,
            ftol=1e-12,
            xtol=1e-12,
            gtol=1e-12,
        )
        if best is None or r.cost < best.cost - 1e-12:
            best = r
    # a level that ends on the search's lower bound is a source the figures do not
    # need: it is set to the bound exactly (its value is then reproducible; the
    # fitted optimum in that direction is flat)
    x = np.where(best.x < lo + LOWER_BOUND_SNAP, lo, best.x)
    levels = tuple(float(v) for v in 10.0**x)
    vals = bank_figures(ctx, reading=reading, basis=basis, levels=levels)
    return DisturbanceFit(shape, levels, subset, reading, vals, float(2 * best.cost))


# ----------------------------------------------------------------------- search
@dataclass(frozen=True, eq=False)
class DisturbanceSearch:
    """Every candidate of the disturbance search and what it shows.

    Attributes
    ----------
    candidates : list of DisturbanceFit
        One per (reading, subset, shape).
    """

    candidates: list

    def best(self, subset: str | None = None, reading: str | None = None):
        """Best candidate by :meth:`DisturbanceFit.score` among the main subsets'
        fits (optionally one subset or reading)."""
        c = [
            x
            for x in self.candidates
            if (x.subset in MAIN_SUBSETS if subset is None else x.subset == subset)
            and (reading is None or x.reading == reading)
        ]
        return min(c, key=lambda x: x.score())

    def section_set(self, subset: str, reading: str = "crossover") -> DisturbanceFit:
        """The calibration of one section: among the fits to that section's figures,
        the fewest violated own targets, then the simplest shape, then the cost."""
        c = [x for x in self.candidates if x.subset == subset and x.reading == reading]

        def key(x: DisturbanceFit):
            own = sum(1 for k in x.targets if not within(FIGURES[k], x.figures[k]))
            return (own, x.shape.simplicity, x.cost)

        return min(c, key=key)

    def joint(self) -> list:
        """Candidates meeting every quantitative figure of both sections and the
        sensor bound (empty when the paper's numbers cannot co-exist)."""
        return [x for x in self.candidates if not x.violated(_QUANT)]

    def conflicts(self, reading: str) -> list[dict]:
        """For each quantitative figure, what dropping it buys.

        Returns
        -------
        list of dict
            ``figure``, ``fewest_violated_without`` (the fewest other quantitative
            figures violated by a candidate fitted to all but this one) and
            ``violated`` (their keys).
        """
        out = []
        for k in _QUANT:
            sub = f"all-but-{k}"
            c = [x for x in self.candidates if x.subset == sub and x.reading == reading]
            if not c:
                continue
            others = tuple(q for q in _QUANT if q != k)
            b = min(c, key=lambda x: (len(x.violated(others)), x.cost))
            out.append(
                {
                    "figure": k,
                    "fewest_violated_without": len(b.violated(others)),
                    "violated": b.violated(others),
                }
            )
        return out


def _uses_reading(subset: str) -> bool:
    return bool(set(SUBSETS[subset]) & {"real_rms_0075_s33", "real_rms_0175_s33"})


def search_disturbances(
    machine: Machine,
    *,
    shapes=SHAPE_GRID,
    subsets=MAIN_SUBSETS,
    readings=READINGS,
    leave_one_out: int = 12,
    ctx=None,
    progress=None,
) -> DisturbanceSearch:
    """Fit every shape to every subset of figures, for both readings of 3.3.

    Parameters
    ----------
    machine : Machine
        Machine with its structure and controller rule (disturbances unused).
    shapes : sequence of Shape, default: SHAPE_GRID
    subsets : sequence of str, default: MAIN_SUBSETS
        Names in :data:`SUBSETS`.
    readings : sequence of str, default: READINGS
    leave_one_out : int, default: 12
        Also fit the ``all-but-<figure>`` subsets on this many shapes (the best of
        subset ``"all"`` per reading), for :meth:`DisturbanceSearch.conflicts`;
        0 to skip.
    ctx : object, optional
        A bank from :func:`make_bank` (built when omitted).
    progress : callable, optional
        Wraps the iterable of shapes.

    Returns
    -------
    DisturbanceSearch
        Every candidate. A subset that does not involve section 3.3's figures is
        fitted once and evaluated under both readings.
    """
    ctx = ctx if ctx is not None else make_bank(machine)
    shapes = tuple(shapes)
    bases = {}
    cands: list[DisturbanceFit] = []
    it = progress(shapes) if progress is not None else shapes
    for shape in it:
        bases[shape] = _basis(ctx, shape)
        for subset in subsets:
            cands.extend(_fit_readings(ctx, shape, subset, readings, bases[shape]))
    if leave_one_out and "all" in subsets:
        loo = [k for k in SUBSETS if k.startswith("all-but-")]
        for reading in readings:
            ranked = sorted(
                (c for c in cands if c.subset == "all" and c.reading == reading),
                key=lambda c: c.cost,
            )[:leave_one_out]
            for c in ranked:
                for subset in loo:
                    if _uses_reading(subset):
                        cands.append(
                            fit_levels(
                                ctx, c.shape, subset, reading=reading,
                                basis=bases[c.shape],
                            )
                        )
                    else:
                        cands.extend(
                            f for f in _fit_readings(
                                ctx, c.shape, subset, (reading,), bases[c.shape]
                            )
                        )
    return DisturbanceSearch(cands)


def _fit_readings(ctx, shape, subset, readings, basis) -> list[DisturbanceFit]:
    """One fit per reading, or one fit evaluated under each reading."""
    if _uses_reading(subset):
        return [
            fit_levels(ctx, shape, subset, reading=r, basis=basis) for r in readings
        ]
    fit = fit_levels(ctx, shape, subset, reading="crossover", basis=basis)
    out = []
    for r in readings:
        vals = bank_figures(ctx, reading=r, basis=basis, levels=fit.levels)
        out.append(dataclasses.replace(fit, reading=r, figures=vals))
    return out
