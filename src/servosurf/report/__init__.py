"""Reports: the paper table (targets, predictions, checks), the metrology summary of
a simulation (one flat-face Ra definition), the realisation study over many seeds,
the flat face's Ra by model part, measured maps and profiles against simulated
ones, and the roughness of an NC-program run.

Analyses return result objects (:class:`SimulationAnalysis`,
:class:`MapComparison`, :class:`ProfileComparison`, :class:`RealisationStudy`):
``.to_dict()`` is the JSON a command writes, ``.plot(folder)`` draws the figures
through :mod:`servosurf.viz`.
"""

from ._analysis import MapComparison, SimulationAnalysis
from ._compare import PEAK_MATCH_RTOL, compare_surfaces
from ._flatface import (
    BUDGET_STEPS,
    PAPER_FLAT_RA,
    FlatFaceBudget,
    FlatFaceModel,
    flat_face_budget,
)
from ._nc import analyse_nc, centre_profile
from ._paper import GROUPS, ROLES, Row, figure_row, paper_table, row_group
from ._peaks import lenslet_peak_study
from ._profile_compare import ProfileComparison, as_profile_or_none, compare_profiles
from ._realisations import (
    REALISATION_METRICS,
    RealisationStudy,
    match_lines,
    realisation_study,
)
from ._simulation import (
    FLAT_RA_DEFINITION,
    HIGH_PASS_CUTOFF,
    PEAK_FMIN,
    analyse,
    flat_face_ra,
)

__all__ = [
    "GROUPS",
    "ROLES",
    "Row",
    "figure_row",
    "paper_table",
    "row_group",
    "lenslet_peak_study",
    "ProfileComparison",
    "compare_profiles",
    "as_profile_or_none",
    "compare_surfaces",
    "MapComparison",
    "PEAK_MATCH_RTOL",
    "analyse_nc",
    "centre_profile",
    "analyse",
    "SimulationAnalysis",
    "flat_face_ra",
    "FLAT_RA_DEFINITION",
    "HIGH_PASS_CUTOFF",
    "PEAK_FMIN",
    "realisation_study",
    "RealisationStudy",
    "REALISATION_METRICS",
    "match_lines",
    "flat_face_budget",
    "FlatFaceBudget",
    "FlatFaceModel",
    "BUDGET_STEPS",
    "PAPER_FLAT_RA",
]
