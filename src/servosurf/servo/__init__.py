"""Mechatronic model of the FTS: plant (Eqs 1-7), PIDF, tuning, closed loop."""

from ..io import read_frf_csv, write_frf_csv  # the FRF file format, re-exported
from ._axis import AXIS_MODELS, AxisModel
from ._ident import (
    DEFAULT_IDENT_PARAMS,
    Identification,
    fit_percent,
    get_param,
    identify,
    open_loop_frf,
    set_param,
)
from ._loop import PATHS, PIDF, LoopFRF, ServoLoop, double_pole, tune_pidf
from ._machine import (
    PROVENANCE_KINDS,
    Actuator,
    Controller,
    Disturbances,
    Machine,
    Mechanics,
    PSDModel,
    Sensor,
    Spindle,
    builtin_machines,
    describe_machine,
    load_machine,
)
from ._perturb import (
    NL_FIELDS,
    LoopPerturbation,
    Nonlinearity,
    StructuralMode,
)
from ._plant import Plant, paper_eq_frf, plant_from_machine

__all__ = [
    "double_pole",
    "AxisModel",
    "AXIS_MODELS",
    "PROVENANCE_KINDS",
    "Actuator",
    "Controller",
    "Disturbances",
    "Machine",
    "Mechanics",
    "PSDModel",
    "Sensor",
    "Spindle",
    "builtin_machines",
    "describe_machine",
    "load_machine",
    "Plant",
    "paper_eq_frf",
    "plant_from_machine",
    "DEFAULT_IDENT_PARAMS",
    "Identification",
    "fit_percent",
    "get_param",
    "identify",
    "open_loop_frf",
    "read_frf_csv",
    "set_param",
    "write_frf_csv",
    "PIDF",
    "LoopFRF",
    "ServoLoop",
    "tune_pidf",
    "PATHS",
    "LoopPerturbation",
    "Nonlinearity",
    "StructuralMode",
    "NL_FIELDS",
]
