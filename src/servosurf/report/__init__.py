"""Reports: the paper table (targets, predictions, checks) and surface analyses."""

from ._paper import GROUPS, ROLES, Row, figure_row, paper_table, row_group
from ._peaks import lenslet_peak_study

__all__ = [
    "GROUPS",
    "ROLES",
    "Row",
    "figure_row",
    "paper_table",
    "row_group",
    "lenslet_peak_study",
]
