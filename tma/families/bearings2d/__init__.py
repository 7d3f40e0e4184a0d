"""``bearings2d``: bearings-only TMA of a constant-velocity target
(``../shared/specs/bearings2d.md``)."""

from tma.families import Family

FAMILY = Family("bearings2d", estimators={
    "lm": "tma.families.bearings2d.estimators.lm:LevenbergMarquardt",
    "nbearings": "tma.families.bearings2d.estimators.nbearings:NBearings",
    "iv": "tma.families.bearings2d.estimators.iv:InstrumentalVariable",
    "mpekf": "tma.families.bearings2d.estimators.mpekf:ModifiedPolarEKF",
    "last_leg": "tma.families.bearings2d.estimators.last_leg:LastLeg",
})
