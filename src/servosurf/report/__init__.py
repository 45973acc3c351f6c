"""Reports: the seed-paper table, and measured profiles against simulated ones."""

from ._paper import GROUPS, Row, paper_table, row_group
from ._profile_compare import ProfileComparison, compare_profiles

__all__ = [
    "GROUPS",
    "Row",
    "paper_table",
    "row_group",
    "ProfileComparison",
    "compare_profiles",
]
