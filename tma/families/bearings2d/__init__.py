"""``bearings2d``: bearings-only TMA of a constant-velocity target
(``docs/families.md``)."""

from tma.families import Family

FAMILY = Family("bearings2d", estimator_paths=(
    "tma.families.bearings2d.estimators.lm:LevenbergMarquardt",
    "tma.families.bearings2d.estimators.nbearings:NBearings",
    "tma.families.bearings2d.estimators.iv:InstrumentalVariable",
    "tma.families.bearings2d.estimators.mpekf:ModifiedPolarEKF",
    "tma.families.bearings2d.estimators.last_leg:LastLeg",
))
