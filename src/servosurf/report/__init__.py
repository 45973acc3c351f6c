"""Reports: the seed-paper table, measured profiles against simulated ones, and the
roughness of an NC-program run."""

from ._nc import analyse_nc, centre_profile
from ._paper import GROUPS, Row, paper_table, row_group
from ._profile_compare import ProfileComparison, compare_profiles

__all__ = [
    "GROUPS",
    "Row",
    "paper_table",
    "row_group",
    "ProfileComparison",
    "compare_profiles",
    "analyse_nc",
    "centre_profile",
]
