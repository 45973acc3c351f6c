"""Reports: the paper table (targets, predictions, checks), the metrology summary of
a simulation (one flat-face Ra definition), the flat face's Ra by model part,
measured profiles against simulated ones, and the roughness of an NC-program run."""

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
from ._profile_compare import ProfileComparison, compare_profiles
from ._simulation import FLAT_RA_DEFINITION, analyse, flat_face_ra

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
    "analyse_nc",
    "centre_profile",
    "analyse",
    "flat_face_ra",
    "FLAT_RA_DEFINITION",
    "flat_face_budget",
    "FlatFaceBudget",
    "FlatFaceModel",
    "BUDGET_STEPS",
    "PAPER_FLAT_RA",
]
