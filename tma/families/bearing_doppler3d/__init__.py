"""``bearing_doppler3d``: underwater bearing-Doppler tracking of a manoeuvring AUV
(``docs/families.md``)."""

from tma.families import Family

FAMILY = Family("bearing_doppler3d", estimator_paths=(
    "tma.families.bearing_doppler3d.estimators.ekf:EKF",
    "tma.families.bearing_doppler3d.estimators.srekf:SquareRootEKF",
    "tma.families.bearing_doppler3d.estimators.cmnf:CMNF",
    "tma.families.bearing_doppler3d.estimators.prior_mean:PriorMean",
))
