"""The catalogue of left-out physics: one module per effect.

Each module here holds one catalogue effect (DISCOVERY.md section 4): its frozen
parameter dataclass (every field with SI unit, physical bounds and their source),
its physics hooks (the hook protocol of :func:`servosurf.simulation.simulate`, so a
fitted effect simulates with ``simulate(spec, hooks=model.hooks())``), its
evidence-to-configuration rule, its search (templates, start, free parameters, an
optional refinement) and its report. :mod:`._base` defines the protocol
(:class:`EffectParams`, :class:`Effect`, :class:`Model`, :class:`Evidence`). The
diagnosis's engine, blocks, locators and report know no effect by name.

Adding an effect (the 23rd)
---------------------------
1. Write ``_my_effect.py`` next to the others: a frozen ``MyEffectParams(EffectParams)``
   with ``effect = "my-effect"``, every field declared with :func:`quantity` (unit,
   ``low``/``high`` physical bounds, ``source``), and the hook methods its physics
   needs (``perturbation``, ``nonlinearity``, ``base_lines``, ``machine``,
   ``workpiece``, ``tool`` + ``edge`` (+ ``tool_at`` + ``edge_at`` for a tool
   changing in time), ``cutting_rules``, ``path_z``, ``surface`` +
   ``surface_heights``); and a ``MyEffect(Effect)`` with its documentation,
   ``channels``, ``params = MyEffectParams``, ``columns``, ``start`` and ``free``
   (``configs``, ``refine`` and ``channel_bar`` when it needs them).
2. Add one line ``MyEffect(),`` to :data:`CATALOGUE` below.

The parametrized contract test (``tests/diagnose/test_effects.py``) then checks it
with every other effect: its parameters change only the recordings its channels
name, removing it returns the nominal model, its report keys are its fields with
units, its bounds have sources, and its hooks simulate as the diagnosis models them.
"""

from __future__ import annotations

from ._amplifier_saturation import AmplifierSaturationEffect, AmplifierSaturationParams
from ._base import (
    Bound,
    Config,
    Effect,
    EffectParams,
    Evidence,
    Free,
    Model,
    Nominal,
    TwoCoefficientEffect,
    quantity,
    set_catalogue_order,
    unit_suffix,
)
from ._base_lines import BaseLineParams, BaseLinesEffect
from ._converter_quantisation import (
    ConverterQuantisationEffect,
    ConverterQuantisationParams,
)
from ._cutting_force_coefficient import (
    CuttingForceCoefficientEffect,
    CuttingForceCoefficientParams,
)
from ._elastic_recovery import ElasticRecoveryEffect, ElasticRecoveryParams
from ._flexure_hysteresis import FlexureHysteresisEffect, FlexureHysteresisParams
from ._flexure_nonlinearity import FlexureNonlinearityEffect, FlexureNonlinearityParams
from ._force_constant_position import (
    ForceConstantPositionEffect,
    ForceConstantPositionParams,
)
from ._friction import FrictionEffect, FrictionParams
from ._loop_delay import LoopDelayEffect, LoopDelayParams
from ._minimum_chip_thickness import (
    MinimumChipThicknessEffect,
    MinimumChipThicknessParams,
)
from ._recalibration import RecalibrationEffect, RecalibrationParams
from ._sensor_noise_shape import SensorNoiseShapeEffect, SensorNoiseShapeParams
from ._sensor_nonlinearity import SensorNonlinearityEffect, SensorNonlinearityParams
from ._sensor_pickup_lines import SensorPickupLinesEffect, SensorPickupParams
from ._spindle_async_error import SpindleAsyncErrorEffect, SpindleAsyncErrorParams
from ._spindle_axial_error import SpindleAxialErrorEffect, SpindleAxialErrorParams
from ._structural_mode import StructuralModeEffect, StructuralModeParams
from ._thermal_drift import ThermalDriftEffect, ThermalDriftParams
from ._tool_edge_waviness import ToolEdgeWavinessEffect, ToolEdgeWavinessParams
from ._tool_radius_error import ToolRadiusErrorEffect, ToolRadiusErrorParams
from ._tool_wear import ToolWearEffect, ToolWearParams

__all__ = [
    "CATALOGUE",
    "get_effect",
    "catalogue_table",
    "Bound",
    "Config",
    "Effect",
    "EffectParams",
    "Evidence",
    "Free",
    "Model",
    "Nominal",
    "TwoCoefficientEffect",
    "quantity",
    "unit_suffix",
    "StructuralModeParams",
    "LoopDelayParams",
    "BaseLineParams",
    "ThermalDriftParams",
    "FlexureNonlinearityParams",
    "ForceConstantPositionParams",
    "AmplifierSaturationParams",
    "SensorNonlinearityParams",
    "SensorNoiseShapeParams",
    "ToolEdgeWavinessParams",
    "ToolRadiusErrorParams",
    "CuttingForceCoefficientParams",
    "SpindleAxialErrorParams",
    "ElasticRecoveryParams",
    "RecalibrationParams",
    "SpindleAsyncErrorParams",
    "ToolWearParams",
    "FlexureHysteresisParams",
    "FrictionParams",
    "ConverterQuantisationParams",
    "SensorPickupParams",
    "MinimumChipThicknessParams",
]

#: The catalogue, in the order ``servosurf diagnose --list`` prints it.
CATALOGUE: tuple[Effect, ...] = (
    StructuralModeEffect(),
    LoopDelayEffect(),
    BaseLinesEffect(),
    ThermalDriftEffect(),
    FlexureNonlinearityEffect(),
    ForceConstantPositionEffect(),
    AmplifierSaturationEffect(),
    SensorNonlinearityEffect(),
    SensorNoiseShapeEffect(),
    ToolEdgeWavinessEffect(),
    ToolRadiusErrorEffect(),
    CuttingForceCoefficientEffect(),
    SpindleAxialErrorEffect(),
    ElasticRecoveryEffect(),
    RecalibrationEffect(),
    SpindleAsyncErrorEffect(),
    ToolWearEffect(),
    FlexureHysteresisEffect(),
    FrictionEffect(),
    ConverterQuantisationEffect(),
    SensorPickupLinesEffect(),
    MinimumChipThicknessEffect(),
)

set_catalogue_order([e.name for e in CATALOGUE])


def get_effect(name: str) -> Effect:
    """The catalogue effect called ``name``.

    Raises
    ------
    KeyError
        When no catalogue effect has that name.
    """
    for e in CATALOGUE:
        if e.name == name:
            return e
    raise KeyError(name)


def catalogue_table() -> list[dict]:
    """The catalogue as JSON-ready dicts (name, parameters with units, bounds and
    their sources, signature, hooks)."""
    return [e.describe() for e in CATALOGUE]
