"""The protocol of a catalogue effect: parameters, model, evidence, search.

A catalogue effect is two classes in one module:

* a frozen **parameter dataclass** (subclass of :class:`EffectParams`): every field
  an SI quantity declared with :func:`quantity` (unit, physical bounds and the
  source of those bounds), and the effect's **physics hooks**, methods of the hook
  protocol of :func:`servosurf.simulation.simulate` (:mod:`servosurf._hooks`):
  ``perturbation()``, ``nonlinearity()``, ``base_lines()``, ``machine(m)``,
  ``workpiece(w)``, ``tool(t)``, ``path_z(t, theta, r, z)``, ``surface(s, ctx)``.
  Where the diagnosis evaluates heights pointwise instead of on a grid, the hook
  has a pointwise twin: ``tool`` comes with ``edge(phi) -> (dR, W)`` and
  ``surface`` with ``surface_heights(z, top) -> z``. An instance is itself a hook:
  ``simulate(spec, hooks=model.hooks())`` simulates a fitted model;
* an :class:`Effect` (the catalogue entry): its documentation, the recording
  kinds it shows in, and its search: configurations placed by the
  :class:`Evidence` the locator gathered, template models, a start from linear
  coefficients, the free parameters of the nonlinear fit, an optional refinement
  search and the report.

A :class:`Model` is the composition the diagnosis fits: effect name -> tuple of
parameter instances (one per term). Its cache keys come from the hook methods each
parameter class defines (:meth:`EffectParams.groups`): a block that depends on the
loop perturbation is keyed on the terms that have a ``perturbation`` hook, with no
list of knobs kept by hand.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..._hooks import HOOKS

__all__ = [
    "Bound",
    "quantity",
    "unit_suffix",
    "EffectParams",
    "Model",
    "Config",
    "Free",
    "Nominal",
    "Evidence",
    "Effect",
    "TwoCoefficientEffect",
    "set_catalogue_order",
    "AT_BOUND",
]

#: A fitted parameter closer than this share of its search range to an end of the
#: range sits at a bound (the fit wanted to go further): the term is refused.
AT_BOUND = 1e-4

#: Pointwise twins the diagnosis calls for some hooks (see the module docstring).
POINTWISE = {"tool": "edge", "surface": "surface_heights"}


@dataclass(frozen=True)
class Bound:
    """A physical bound that depends on the case or on another parameter.

    Parameters
    ----------
    text : str
        The bound as a formula (``"0.45 fs"``), for the catalogue table.
    fn : callable
        ``fn(evidence, params) -> float`` in the parameter's SI unit.
    """

    text: str
    fn: Callable[[Any, Any], float]

    def __call__(self, evidence, params) -> float:
        return float(self.fn(evidence, params))


def quantity(default: Any = dataclasses.MISSING, *, unit: str, doc: str,
             low: float | Bound | None, high: float | Bound | None, source: str,
             fitted: bool = True) -> Any:
    """Declare a parameter field: SI unit, meaning, physical bounds and their source.

    Parameters
    ----------
    default : object, optional
        Default value (omit for a required field).
    unit : str
        SI unit (``"1"`` for a dimensionless number).
    doc : str
        One-line meaning.
    low, high : float, Bound or None
        Physical bounds (inclusive); None: unbounded on that side.
    source : str
        Where the bounds come from (a citation or the physical argument with its
        numbers).
    fitted : bool, default: True
        Whether the nonlinear fit moves it (False: set from the configuration or
        the evidence, e.g. a spindle order).

    Returns
    -------
    dataclasses.Field
        The field, its metadata holding the above.
    """
    meta = {"unit": unit, "doc": doc, "low": low, "high": high, "source": source,
            "fitted": fitted}
    if default is dataclasses.MISSING:
        return dataclasses.field(metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


_SUFFIX = {
    "1": "",
    "m": "m",
    "s": "s",
    "Hz": "hz",
    "A": "a",
    "kg": "kg",
    "rad": "rad",
    "m/s": "m_per_s",
    "m/N": "m_per_n",
    "N/m": "n_per_m",
    "N/m^2": "n_per_m2",
    "N/m^3": "n_per_m3",
    "N s/m": "n_s_per_m",
    "N/A": "n_per_a",
    "1/m": "per_m",
    "1/m^2": "per_m2",
    "m/sqrt(Hz)": "m_per_sqrt_hz",
    "N": "n",
    "V": "v",
}


def unit_suffix(unit: str) -> str:
    """The JSON key suffix of an SI unit (``"m/N"`` -> ``"m_per_n"``; ``""`` for 1)."""
    try:
        return _SUFFIX[unit]
    except KeyError:
        raise ValueError(f"no key suffix for unit {unit!r}") from None


def _evaluate(b, evidence, params) -> float | None:
    if b is None:
        return None
    if isinstance(b, Bound):
        return b(evidence, params)
    return float(b)


@dataclass(frozen=True)
class EffectParams:
    """Base of the parameter dataclass of a catalogue effect (one term).

    Subclasses set :attr:`effect` (the catalogue name) and declare every field with
    :func:`quantity`; their hook methods are the effect's physics.
    """

    effect: ClassVar[str] = ""

    @classmethod
    def groups(cls) -> frozenset[str]:
        """Hook methods this class defines (the cache groups it belongs to)."""
        own = set()
        for k in cls.__mro__:
            if k in (EffectParams, object):
                continue
            own |= {h for h in HOOKS if h in vars(k)}
        return frozenset(own)

    @classmethod
    def quantities(cls) -> tuple[dataclasses.Field, ...]:
        """The fields with their metadata (unit, doc, bounds, source)."""
        return tuple(dataclasses.fields(cls))

    @classmethod
    def report_key(cls, name: str, index: int | None = None) -> str:
        """JSON key of field ``name``: ``name[_index]_unit`` (``frequency_1_hz``)."""
        f = next(f for f in dataclasses.fields(cls) if f.name == name)
        suf = unit_suffix(f.metadata["unit"])
        key = name if index is None else f"{name}_{index}"
        return f"{key}_{suf}" if suf else key

    def report(self, index: int | None = None) -> dict[str, float]:
        """Parameter values in SI units under unit-suffixed keys (None omitted)."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            out[self.report_key(f.name, index)] = float(v)
        return out

    def bounds(self, evidence) -> dict[str, tuple[float | None, float | None]]:
        """Physical bounds ``(low, high)`` of every field in its SI unit."""
        return {
            f.name: (_evaluate(f.metadata["low"], evidence, self),
                     _evaluate(f.metadata["high"], evidence, self))
            for f in dataclasses.fields(self)
        }

    def implausible(self, evidence) -> str | None:
        """Why a value lies outside its physical bounds (None: all inside)."""
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            lo = _evaluate(f.metadata["low"], evidence, self)
            hi = _evaluate(f.metadata["high"], evidence, self)
            u = f.metadata["unit"]
            u = "" if u == "1" else f" {u}"
            if not math.isfinite(float(v)):
                return f"{f.name} = {v!r} is not finite"
            if lo is not None and v < lo:
                return (f"{f.name} = {float(v):.4g}{u} is below its physical bound "
                        f"{lo:.4g}{u} ({f.metadata['source']})")
            if hi is not None and v > hi:
                return (f"{f.name} = {float(v):.4g}{u} is above its physical bound "
                        f"{hi:.4g}{u} ({f.metadata['source']})")
        return None


# ------------------------------------------------------------------ model
#: Catalogue order of the effects (set by the catalogue): a model's terms are kept
#: in this order, so equal models compose their hooks in the same order.
_RANK: dict[str, int] = {}


def set_catalogue_order(names) -> None:
    """Record the catalogue order of effect names (called by the catalogue)."""
    _RANK.clear()
    _RANK.update({n: i for i, n in enumerate(names)})


def _rank(name: str) -> tuple[int, str]:
    return (_RANK.get(name, len(_RANK)), name)


@dataclass(frozen=True)
class Model:
    """A diagnosis model: effect name -> tuple of parameter instances (terms).

    ``Model()`` is the nominal machine. Models are immutable and hashable; the
    terms are kept in catalogue order.

    Parameters
    ----------
    terms : tuple of (str, tuple of EffectParams)
        The effects and their terms (empty tuples are dropped).
    """

    terms: tuple[tuple[str, tuple[EffectParams, ...]], ...] = ()

    def __post_init__(self) -> None:
        items = []
        for name, ps in self.terms:
            ps = tuple(ps)
            for q in ps:
                if q.effect != name:
                    raise ValueError(f"{type(q).__name__} belongs to {q.effect!r}, "
                                     f"not {name!r}")
            if ps:
                items.append((name, ps))
        names = [n for n, _ in items]
        if len(set(names)) != len(names):
            raise ValueError(f"an effect appears twice in a model: {names}")
        items.sort(key=lambda t: _rank(t[0]))
        object.__setattr__(self, "terms", tuple(items))

    @classmethod
    def of(cls, *params: EffectParams) -> Model:
        """A model of the given terms (several of one effect keep their order)."""
        m = cls()
        for q in params:
            m = m.add(q)
        return m

    # ---------------------------------------------------------------- access
    def get(self, name: str) -> tuple[EffectParams, ...]:
        """The terms of effect ``name`` (empty when absent)."""
        for n, ps in self.terms:
            if n == name:
                return ps
        return ()

    def __contains__(self, name: object) -> bool:
        return any(n == name for n, _ in self.terms)

    @property
    def names(self) -> tuple[str, ...]:
        """Effects present, in catalogue order."""
        return tuple(n for n, _ in self.terms)

    @property
    def is_nominal(self) -> bool:
        """True for the nominal machine (no term)."""
        return not self.terms

    def hooks(self, group: str | None = None) -> tuple[EffectParams, ...]:
        """Every term in catalogue order (only those with hook ``group`` if given)."""
        out = []
        for _, ps in self.terms:
            for q in ps:
                if group is None or group in type(q).groups():
                    out.append(q)
        return tuple(out)

    def key(self, groups) -> tuple:
        """Cache key of what depends on the hook ``groups`` only."""
        g = set(groups)
        out = []
        for n, ps in self.terms:
            if ps and type(ps[0]).groups() & g:
                out.append((n, ps))
        return tuple(out)

    # ---------------------------------------------------------------- change
    def with_terms(self, name: str, params) -> Model:
        """Effect ``name`` with exactly the terms ``params`` (none: removed)."""
        rest = tuple((n, ps) for n, ps in self.terms if n != name)
        return Model(rest + ((name, tuple(params)),))

    def add(self, params: EffectParams) -> Model:
        """One more term of the effect of ``params``."""
        return self.with_terms(params.effect, self.get(params.effect) + (params,))

    def replace_term(self, name: str, slot: int, params: EffectParams) -> Model:
        """Term ``slot`` of effect ``name`` replaced by ``params``."""
        ps = list(self.get(name))
        ps[slot] = params
        return self.with_terms(name, ps)

    def without(self, name: str, slot: int | None = None) -> Model:
        """Effect ``name`` removed (only its term ``slot`` when given)."""
        if slot is None:
            return self.with_terms(name, ())
        ps = list(self.get(name))
        del ps[slot]
        return self.with_terms(name, ps)

    def merge(self, other: Model) -> Model:
        """The terms of both models (``other``'s appended per effect)."""
        m = self
        for q in other.hooks():
            m = m.add(q)
        return m


# ------------------------------------------------------------------ search
@dataclass(frozen=True)
class Config:
    """One configuration of an effect (its fixed nonlinear parameters).

    Parameters
    ----------
    label : str
        Human-readable label.
    values : dict
        The fixed parameters (effect-specific keys; not compared or hashed).
    """

    label: str
    values: dict = field(default_factory=dict, hash=False, compare=False)


@dataclass(frozen=True)
class Free:
    """A free parameter of the nonlinear fit: field ``field`` of term ``slot`` of
    effect ``effect``, searched in ``[lo, hi]`` (in log space when ``log``).

    ``located`` marks a location the effect's own search finds on all the data
    (a line's frequency, resolved to ``1 / T`` of the longest record): the
    leave-one-recording-out refit holds it, since the other recordings may be
    too short to resolve it, and judges the remaining parameters (the amplitude
    a line must show in the recording left out)."""

    name: str
    effect: str
    slot: int
    field: str
    lo: float
    hi: float
    log: bool = False
    located: bool = False

    def get(self, model: Model) -> float:
        """Current value (SI)."""
        return float(getattr(model.get(self.effect)[self.slot], self.field))

    def set(self, model: Model, value: float) -> Model:
        """The model with the value set."""
        q = model.get(self.effect)[self.slot]
        q = dataclasses.replace(q, **{self.field: float(value)})
        return model.replace_term(self.effect, self.slot, q)

    def at_bound(self, model: Model) -> bool:
        """Whether the value sits at an end of the search range."""
        v = self.get(model)
        if self.log:
            if not v > 0:
                return True
            x, lo, hi = math.log(v), math.log(self.lo), math.log(self.hi)
        else:
            x, lo, hi = v, self.lo, self.hi
        tol = AT_BOUND * (hi - lo)
        if not self.log and lo == 0.0:
            # zero is a magnitude's natural floor, not a search limit: a small
            # amplitude is small, only one pinned at zero sits at the bound
            return x <= 0.0 or hi - x <= tol
        return x - lo <= tol or hi - x <= tol


# ------------------------------------------------------------------ evidence
@dataclass(frozen=True)
class Nominal:
    """Nominal values of the case's machine and workpiece (SI).

    Parameters
    ----------
    moving_mass : float
        m1 + m2, kg.
    flexure_stiffness : float
        k2, N/m.
    flexure_damping : float
        c2, N s/m (at least 1e-3: the recalibration searches in log space).
    force_constant : float
        B l, N/A.
    sensor_bandwidth : float
        Position sensor -3 dB bandwidth, Hz.
    delay : float
        Controller computation delay beyond the ZOH, in controller samples.
    sensor_floor : float
        White floor of the sensor noise, m/sqrt(Hz).
    sensor_corner : float
        Roll-off corner of the sensor noise, Hz.
    sensor_level : float
        Sensor noise amplitude density at 1 kHz, m/sqrt(Hz).
    specific_force : float
        Thrust force per chip area k_t, N/m^2.
    max_current : float
        The amplifier's rated current limit, A.
    tool_radius : float
        Nose radius of the case's tool, m.
    """

    moving_mass: float = 0.075
    flexure_stiffness: float = 2e4
    flexure_damping: float = 2.0
    force_constant: float = 8.0
    sensor_bandwidth: float = 15e3
    delay: float = 1.0
    sensor_floor: float = 0.0
    sensor_corner: float = 15e3
    sensor_level: float = 1e-12
    specific_force: float = 2.6e9
    max_current: float = 3.0
    tool_radius: float = 0.5e-3


@dataclass(frozen=True, eq=False)
class Evidence:
    """What the locators found and what the case is: the input of every effect's
    evidence-to-configuration rule, built by :func:`servosurf.diagnose.gather`.

    Parameters
    ----------
    fs : float
        Controller rate, Hz.
    fts : float, default: 0.0
        FTS (lenslet) frequency in Hz, 0 without a lenslet toolpath.
    stroke : float, default: 10e-6
        Largest commanded tool excursion, m.
    record_length : float, default: 4096
        Length of the idle records in controller samples (line bin width
        ``fs / record_length``).
    mismatches : tuple of Mismatch
        Located departures from the noise model (of the model located).
    frf_peaks : tuple of float
        Frequencies (Hz) of the largest nominal FRF residual peaks.
    order_candidates : tuple of int
        Spindle orders most significant on the maps and profiles.
    current_demand : ndarray
        Absolute current demand (A) of the nominal model's command records.
    kinds : frozenset of str
        Recording kinds present.
    recording_kinds : mapping of str to str
        Recording name -> kind.
    nominal : Nominal
        The case's nominal machine and workpiece values.
    case : CaseModel, optional
        The case (for evidence that needs the loop, e.g. a line's noise level).
    previous : Evidence, optional
        The evidence of the nominal model when this one was located on a
        residual (rules that keep what was found first read it).
    """

    fs: float
    fts: float = 0.0
    stroke: float = 10e-6
    record_length: float = 4096.0
    mismatches: tuple = ()
    frf_peaks: tuple[float, ...] = ()
    order_candidates: tuple[int, ...] = ()
    current_demand: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kinds: frozenset[str] = frozenset()
    recording_kinds: Mapping[str, str] = field(default_factory=dict)
    nominal: Nominal = field(default_factory=Nominal)
    case: Any = None
    previous: Evidence | None = None
    _memo: dict = field(default_factory=dict, repr=False)

    def memo(self, key, fn):
        """``fn()`` computed once per evidence object under ``key``."""
        if key not in self._memo:
            self._memo[key] = fn()
        return self._memo[key]


# ------------------------------------------------------------------ effect
class Effect:
    """A catalogue effect: documentation, parameters and search.

    Attributes
    ----------
    name, title, physics, signature, confused_with : str
        Documentation.
    channels : tuple of str
        Recording kinds where the effect is visible.
    params : type
        Its :class:`EffectParams` subclass.
    max_terms : int
        How many terms of this effect a model may hold.
    recalibration : bool
        A recalibration of machine parameters, reported apart from physics.
    require : tuple or None
        ``(domain, min deviance reduction)``: when blocks of that domain exist, an
        accepted term must reduce their deviance at least this much (channel logic).
    n_start : int
        Configurations fitted per round (several for multimodal parameters).
    threshold : bool
        A single threshold level: searched on the deviance itself over every
        configuration (its linearised score says nothing).
    """

    name = ""
    title = ""
    physics = ""
    signature = ""
    confused_with = ""
    channels: tuple[str, ...] = ()
    params: type[EffectParams] = EffectParams
    max_terms = 1
    recalibration = False
    require: tuple | None = None
    n_start = 1
    threshold = False

    @property
    def groups(self) -> frozenset[str]:
        """Hook groups of the effect's parameters (the blocks it can change)."""
        return self.params.groups()

    def must_beat_physics(self, cfg: Config | None = None) -> bool:
        """Whether a term in configuration ``cfg`` pays the selection's extra
        recalibration penalty (it must clearly beat physics). Plant
        recalibrations do; a nuisance the model leaves out on purpose (noise
        levels off by a factor, issue 19 item 5) must not, or a physical
        mechanism with the same spectral reach is named in its place."""
        return self.recalibration

    def n_params(self, cfg: Config | None = None) -> int:
        """Parameters counted by the selection criterion per term."""
        return sum(1 for f in self.params.quantities() if f.metadata["fitted"])

    def slots(self, model: Model) -> int:
        """Number of terms of this effect in ``model``."""
        return len(model.get(self.name))

    def active(self, model: Model) -> bool:
        """Whether ``model`` holds a term of this effect."""
        return self.name in model

    def term(self, model: Model, slot: int) -> EffectParams:
        """Term ``slot`` of this effect in ``model``."""
        return model.get(self.name)[slot]

    def configs(self, ev: Evidence, model: Model) -> list[Config]:
        """Candidate configurations placed by the evidence."""
        return [Config("default")]

    def columns(self, model: Model, cfg: Config, ev: Evidence):
        """Template models ``[(model_i, probe_i)]``: one per linear direction."""
        raise NotImplementedError  # pragma: no cover

    def start(self, model: Model, cfg: Config, coefs, ev: Evidence) -> Model:
        """Model with a new term started from the linear coefficients."""
        raise NotImplementedError  # pragma: no cover

    def free(self, model: Model, slot: int, ev: Evidence,
             cfg: Config | None = None) -> list[Free]:
        """Free parameters of term ``slot`` for the nonlinear fit."""
        raise NotImplementedError  # pragma: no cover

    def refine(self, engine, model: Model, term) -> Model:
        """Search before the local fit of a new term (default: a threshold effect's
        level search on the deviance, else nothing)."""
        if self.threshold:
            return engine.level_search(self.remove(model, term.slot), self, term)
        return model

    def distinct(self, cfg: Config, previous: list[Config]) -> bool:
        """Whether a further start ``cfg`` differs enough from those fitted this
        round (only effects with ``n_start > 1`` are asked)."""
        return False

    def channel_bar(self, model: Model, slot: int, ev: Evidence,
                    expected: float) -> float:
        """Deviance reduction the ``require`` blocks must show for term ``slot``.

        ``expected`` is the reduction the term predicts there if it is true. The
        default is the fixed bar of ``require``.
        """
        return self.require[1]

    def report(self, model: Model, slot: int) -> dict[str, float]:
        """Parameter values of term ``slot`` in SI under unit-suffixed keys."""
        index = slot + 1 if self.max_terms > 1 else None
        return self.term(model, slot).report(index)

    def remove(self, model: Model, slot: int) -> Model:
        """Model without term ``slot``."""
        return model.without(self.name, slot)

    def implausible(self, model: Model, slot: int, ev: Evidence,
                    cfg: Config | None = None) -> str | None:
        """Why term ``slot`` cannot be an explanation (None: it can).

        A parameter outside its physical bounds, or a fitted parameter at an end
        of its search range (the likelihood wanted more than the effect allows).
        """
        q = self.term(model, slot)
        why = q.implausible(ev)
        if why is not None:
            return why
        for f in self.free(model, slot, ev, cfg):
            if f.at_bound(model):
                v = f.get(model)
                unit = next(x.metadata["unit"] for x in q.quantities()
                            if x.name == f.field)
                unit = "" if unit == "1" else f" {unit}"
                return (f"{f.field} = {v:.4g}{unit} sits at the bound of its search "
                        f"range [{f.lo:.4g}, {f.hi:.4g}]{unit}")
        return None

    def describe(self) -> dict:
        """JSON-ready catalogue entry (parameters with units, bounds, sources)."""
        pars = []
        for f in self.params.quantities():
            m = f.metadata

            def txt(b):
                if b is None:
                    return None
                return b.text if isinstance(b, Bound) else float(b)

            pars.append({"name": f.name, "unit": m["unit"], "doc": m["doc"],
                         "low": txt(m["low"]), "high": txt(m["high"]),
                         "source": m["source"], "fitted": m["fitted"]})
        return {
            "effect": self.name,
            "title": self.title,
            "physics": self.physics,
            "parameters": pars,
            "signature": self.signature,
            "confused_with": self.confused_with,
            "visible_in": list(self.channels),
            "recalibration": self.recalibration,
            "hooks": sorted(self.groups),
        }


class TwoCoefficientEffect(Effect):
    """An effect with two linear coefficients; configurations pick the sub-form.

    Configurations ``first``, ``second`` and ``both`` let the selection criterion
    prefer the simpler sub-form (one coefficient) when it suffices. Subclasses set
    :attr:`fields` (the two parameter fields), :attr:`labels`, :attr:`bound` (the
    search range in probes) and :meth:`probes`.
    """

    fields: tuple[str, str] = ("", "")
    labels: tuple[str, str] = ("", "")
    bound = 1e5

    def probes(self, ev: Evidence) -> tuple[float, float]:  # pragma: no cover
        """Probe values of the two coefficients (SI)."""
        raise NotImplementedError

    def _current(self, model: Model) -> dict[str, float]:
        ps = model.get(self.name)
        return {f: (getattr(ps[0], f) if ps else 0.0) for f in self.fields}

    def configs(self, ev, model):
        return [
            Config(self.labels[0], {"which": (0,)}),
            Config(self.labels[1], {"which": (1,)}),
            Config("both", {"which": (0, 1)}),
        ]

    def n_params(self, cfg=None):
        return 2 if cfg is None else len(cfg.values["which"])

    def columns(self, model, cfg, ev):
        pr = self.probes(ev)
        out = []
        for i in cfg.values["which"]:
            kw = self._current(model)
            kw[self.fields[i]] += pr[i]
            out.append((model.with_terms(self.name, (self.params(**kw),)), pr[i]))
        return out

    def start(self, model, cfg, coefs, ev):
        pr = self.probes(ev)
        kw = dict.fromkeys(self.fields, 0.0)
        for c, i in zip(coefs, cfg.values["which"], strict=True):
            kw[self.fields[i]] = pr[i] * float(c)
        return model.with_terms(self.name, (self.params(**kw),))

    def free(self, model, slot, ev, cfg=None):
        pr = self.probes(ev)
        which = (0, 1) if cfg is None else cfg.values["which"]
        return [
            Free(self.fields[i], self.name, slot, self.fields[i],
                 -self.bound * pr[i], self.bound * pr[i])
            for i in which
        ]
