"""``radar2d``: vessel tracking by a coastal radar, fuzzy multi-model alpha-beta vs IMM
(``docs/families.md``)."""

from tma.families import Family

FAMILY = Family("radar2d", estimator_paths=(
    "tma.families.radar2d.estimators.alphabeta:AlphaBeta",
    "tma.families.radar2d.estimators.fuzzy_mm:FuzzyMultiModel",
    "tma.families.radar2d.estimators.imm:IMM",
))
