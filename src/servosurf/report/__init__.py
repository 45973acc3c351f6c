"""Reports: the table of seed-paper numbers that servosurf reproduces."""

from ._paper import GROUPS, Row, paper_table, row_group

__all__ = ["GROUPS", "Row", "paper_table", "row_group"]
