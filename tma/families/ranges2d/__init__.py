"""``ranges2d``: range-only navigation, the Bayesian mean by importance sampling
(``docs/families.md``)."""

from tma.families import Family

FAMILY = Family("ranges2d", estimator_paths=(
    "tma.families.ranges2d.estimators.quadrature:Quadrature",
    "tma.families.ranges2d.estimators.prior_is:PriorIS",
    "tma.families.ranges2d.estimators.adaptive_is:AdaptiveIS",
))
