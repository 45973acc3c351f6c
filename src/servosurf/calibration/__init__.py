"""Calibration as code: every calibrated number of the built-in machine, from targets.

The seed paper does not publish its machine's parameters or its disturbance PSDs;
servosurf derives the ones its figures determine, reproducibly, from stated targets
(:data:`FIGURES`, each with its place in the paper), and labels every other number
``paper``, ``assumed`` or ``derived``.
"""

from ._bank import ErrorBank, bandwidth_for_3db, curve_minimum
from ._calibrate import (
    COMPARE_RTOL,
    DISTURBANCE_SETS,
    PARAMETERS,
    ZETA1,
    Calibration,
    base_machine,
    calibrate,
    calibrated_constants,
    compare_constants,
)
from ._cut import LENS5, lenslet_cut, solve_thrust_pressure
from ._disturbances import (
    DISTURBANCE_FIGURES,
    READINGS,
    SHAPE_GRID,
    SUBSETS,
    DisturbanceFit,
    DisturbanceSearch,
    Shape,
    bank_figures,
    fit_levels,
    make_bank,
    search_disturbances,
    shape_of,
    shape_psd,
    to_disturbances,
)
from ._figures import FIGURES, OPTIMUM_FACTOR, RMS_RTOL, PaperFigure, figure, within
from ._mechanisms import critical_pole, overshoot_gap, stability_mechanism
from ._structure import (
    FIG13C_BANDWIDTH,
    HEAVY_MASS,
    StructureParams,
    apply_structure,
    error_peaks,
    limit_near,
    response_at_100hz,
    solve_structure,
    structure_figures,
    structure_of,
)

__all__ = [
    "COMPARE_RTOL",
    "DISTURBANCE_SETS",
    "PARAMETERS",
    "ZETA1",
    "Calibration",
    "base_machine",
    "calibrate",
    "calibrated_constants",
    "compare_constants",
    "LENS5",
    "lenslet_cut",
    "solve_thrust_pressure",
    "critical_pole",
    "overshoot_gap",
    "stability_mechanism",
    "FIG13C_BANDWIDTH",
    "HEAVY_MASS",
    "StructureParams",
    "apply_structure",
    "error_peaks",
    "limit_near",
    "response_at_100hz",
    "solve_structure",
    "structure_figures",
    "structure_of",
    "ErrorBank",
    "bandwidth_for_3db",
    "curve_minimum",
    "DISTURBANCE_FIGURES",
    "READINGS",
    "SHAPE_GRID",
    "SUBSETS",
    "DisturbanceFit",
    "DisturbanceSearch",
    "Shape",
    "bank_figures",
    "fit_levels",
    "make_bank",
    "search_disturbances",
    "shape_of",
    "shape_psd",
    "to_disturbances",
    "FIGURES",
    "OPTIMUM_FACTOR",
    "RMS_RTOL",
    "PaperFigure",
    "figure",
    "within",
]
