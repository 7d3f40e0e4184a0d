"""The contract between the bearings-only base and its estimators: ``Bearings`` and
``TargetMotion`` in, a ``Solution`` out of ``solve``, and the ``JudgedFit`` the base's
``judge`` refines from it (``estimators/base.py``)."""

from dataclasses import dataclass, field

import numpy as np

from tma.families.bearings2d.manoeuvre_prior import ManoeuvrePrior


@dataclass(frozen=True)
class Bearings:
    """One shard's bearings as every estimator takes them: times ``t`` (K,, s), own-ship
    ``own_x``, ``own_y`` (K,, m), the bearings ``measured`` (n, K, rad; 0 where missing),
    ``valid`` (n, K; None: every bearing present, which spares the masks in the hot loops),
    each track's ``first`` and ``last`` bearing (n,), ``n_bearings`` (n,) and the log's
    nominal noise ``sigma_deg`` (None: unknown). Several platforms: ``own_x``, ``own_y`` are
    those of the platform that took each epoch's bearings, ``platform`` (K,) its index into
    ``platforms`` (None: one own-ship); ``reference`` the platform range and bearing now
    are read from, and ``now_x``, ``now_y`` (n,, m) where it was at each track's last bearing
    (``platforms.observer_now``; one own-ship: own-ship there)."""

    t: np.ndarray
    own_x: np.ndarray
    own_y: np.ndarray
    measured: np.ndarray
    valid: np.ndarray | None
    first: np.ndarray
    last: np.ndarray
    n_bearings: np.ndarray
    sigma_deg: float | None
    now_x: np.ndarray | None = None
    now_y: np.ndarray | None = None
    platform: np.ndarray | None = None
    platforms: tuple[str, ...] | None = None
    reference: int = 0


@dataclass(frozen=True)
class TargetMotion:
    """The targets' motion an estimate assumes: random acceleration ``accel_psd_m2_s3`` per
    axis (m^2/s^3; 0: none) and the manoeuvres' prior (None: none)."""

    accel_psd_m2_s3: float
    manoeuvres: ManoeuvrePrior | None = None

    @property
    def moving(self) -> bool:
        return self.accel_psd_m2_s3 > 0 or self.manoeuvres is not None


@dataclass
class Solution:
    """What ``solve`` returns, per track (n,): the estimate ``theta`` (n, 4: x0, y0 (m), vx,
    vy (m/s)), whether it ``converged``, its ``stop_reason`` (0: the F tolerance; what else
    means the estimator's own, named by the report), the cost evaluations ``n_f_evals`` and
    iterations ``n_iter`` (NaN where the estimator has none: a direct solve);
    optional: the fit at theta (``cost_rad2``, F in rad^2, and ``jtj``, the normal matrix
    (n, 4, 4); computed when absent), a noise scale and fit test of the estimator's own
    (``sigma2_rad2``, ``fit_p``: a robust fit's, which replace the nominal ones), the bearings
    it kept (``inliers``, n x K) or fitted (``bearings_used``: part of each track), from when
    the solution holds (``leg_start_s``), and its own output ``columns`` (its ``outputs``)."""

    theta: np.ndarray
    converged: np.ndarray
    stop_reason: np.ndarray
    n_f_evals: np.ndarray
    n_iter: np.ndarray
    cost_rad2: np.ndarray | None = None
    jtj: np.ndarray | None = None
    sigma2_rad2: np.ndarray | None = None
    fit_p: np.ndarray | None = None
    inliers: np.ndarray | None = None
    bearings_used: np.ndarray | None = None
    leg_start_s: np.ndarray | None = None
    columns: dict = field(default_factory=dict)


@dataclass
class JudgedFit:
    """The answer being judged, per track (n,), as ``judge``'s steps refine it: the state
    ``theta`` (n, 4), ``converged``, F ``cost`` (rad^2) and ``jtj`` (n, 4, 4), the noise
    ``sigma2`` (rad^2) and fit test ``fit_p`` (``own_fit_test``: the solver's own), the
    bearings it rests on (``use``, n x K or None: all; ``n_bearings``; from each track's
    bearing ``start``), which tracks the trend test reads (``tested``) and its p-value
    (``motion_p``), the manoeuvre mixture's ``p_manoeuvre``, ``tail_scale``, ``p_omitted``
    and ``n_manoeuvres`` (``ncv.MotionFit``; NaN, and 1 for ``tail_scale``, where none),
    the trajectory tables ``paths``, the tracks whose range own-ship's motion leaves
    ``undetermined``, and the mixture's ``intervals`` (n, 3, 4: range, course, speed now;
    NaN where none: a single Gaussian's are its estimate +- 1 and 2 sd)."""

    theta: np.ndarray
    converged: np.ndarray
    cost: np.ndarray
    jtj: np.ndarray
    sigma2: np.ndarray
    fit_p: np.ndarray
    own_fit_test: bool
    n_bearings: np.ndarray
    use: np.ndarray | None
    start: np.ndarray
    tested: np.ndarray
    motion_p: np.ndarray
    p_manoeuvre: np.ndarray
    tail_scale: np.ndarray
    p_omitted: np.ndarray
    n_manoeuvres: np.ndarray
    undetermined: np.ndarray
    intervals: np.ndarray
    paths: list = field(default_factory=list)
