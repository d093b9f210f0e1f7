"""Which rows of the paper's Table 2 (data/seed_table2.csv) share a pose:
an assumption, as the paper does not say.  Kept apart from the analysis
(commands/table2.py) so that ``robstiff table2 --help`` can show it without
loading the analysis."""

GROUPS = {"A": [1, 2, 3, 4, 5, 6, 17], "B": [7, 8, 9, 10, 11, 12], "C": [13, 14], "D": [15, 16]}
SPLIT_A = {"A1": [1, 2, 3], "A2": [4, 5, 6, 17]}

GROUPING = """\
Grouping of the table's rows by pose (an assumption: the paper does not say which rows share a pose):
  A: rows 1-6 and 17 (-x loads; dx about -2.6 um/N, dy positive, dz small)
  B: rows 7-12 (-x loads; dx about -4 um/N, dz about -2.3 um/N)
  C: rows 13-14 (the same (0, -275, 25) N load twice)
  D: rows 15-16 (the same (-40, -295, 10) N load twice)
Row 17 joins A because its response (-0.934, 0.276, -0.299) mm at 360 N
matches A's other 360 N rows, not B's (-1.43, 0.02, -0.80).  As a check of
that assumption, A is also split into A1 (rows 1-3) and A2 (rows 4-6, 17)."""
