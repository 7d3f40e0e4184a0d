"""``bearing_doppler3d``: underwater bearing-Doppler tracking of a manoeuvring AUV
(``../shared/specs/bearing_doppler3d.md``)."""

from tma.families import Family

FAMILY = Family("bearing_doppler3d", estimators={
    "ekf": "tma.families.bearing_doppler3d.estimators.ekf:EKF",
    "srekf": "tma.families.bearing_doppler3d.estimators.srekf:SquareRootEKF",
    "cmnf": "tma.families.bearing_doppler3d.estimators.cmnf:CMNF",
    "prior_mean": "tma.families.bearing_doppler3d.estimators.prior_mean:PriorMean",
})
