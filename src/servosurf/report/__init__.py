"""Reports: the table of seed-paper numbers that servosurf reproduces, and the
roughness of an NC-program run."""

from ._nc import analyse_nc, centre_profile
from ._paper import GROUPS, Row, paper_table, row_group

__all__ = ["GROUPS", "Row", "paper_table", "row_group", "analyse_nc",
           "centre_profile"]
