"""Reports: the table of seed-paper numbers that servosurf reproduces, the
metrology summary of a simulation (one flat-face Ra definition) and the flat
face's Ra by model part."""

from ._flatface import (
    BUDGET_STEPS,
    PAPER_FLAT_RA,
    FlatFaceBudget,
    FlatFaceModel,
    flat_face_budget,
)
from ._paper import GROUPS, Row, paper_table, row_group
from ._simulation import FLAT_RA_DEFINITION, analyse, flat_face_ra

__all__ = [
    "GROUPS",
    "Row",
    "paper_table",
    "row_group",
    "analyse",
    "flat_face_ra",
    "FLAT_RA_DEFINITION",
    "flat_face_budget",
    "FlatFaceBudget",
    "FlatFaceModel",
    "BUDGET_STEPS",
    "PAPER_FLAT_RA",
]
