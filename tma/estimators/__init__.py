"""Estimator registry: ``name -> class``. Every estimator has the same interface:

``Estimator(config).estimate(log) -> dict[str, ndarray]`` with one ``(n_tracks, ...)`` array
per output column, vectorised over the tracks of a shard. ``Estimator.family`` names the
scenario family whose logs it reads, ``Estimator.Config`` declares its parameters.
"""

import importlib

from tma.config import validate
from tma.errors import ConfigError

ESTIMATORS = {
    "lm": "tma.estimators.lm:LevenbergMarquardt",
    "nbearings": "tma.estimators.nbearings:NBearings",
    "quadrature": "tma.estimators.quadrature:Quadrature",
    "prior_is": "tma.estimators.prior_is:PriorIS",
    "adaptive_is": "tma.estimators.adaptive_is:AdaptiveIS",
    "alphabeta": "tma.estimators.alphabeta:AlphaBeta",
    "fuzzy_mm": "tma.estimators.fuzzy_mm:FuzzyMultiModel",
    "imm": "tma.estimators.imm:IMM",
    "ekf": "tma.estimators.ekf:EKF",
    "srekf": "tma.estimators.srekf:SquareRootEKF",
    "cmnf": "tma.estimators.cmnf:CMNF",
    "prior_mean": "tma.estimators.prior_mean:PriorMean",
}


def estimator_class(name: str):
    if name not in ESTIMATORS:
        raise ConfigError(f"unknown estimator '{name}' (known: {', '.join(sorted(ESTIMATORS))})")
    module, cls = ESTIMATORS[name].split(":")
    return getattr(importlib.import_module(module), cls)


def build_estimator(node):
    """Validate an estimator config node (must hold ``name``) and build the estimator."""
    name = node.get("name") if node is not None else None
    if name is None:
        raise ConfigError("estimator: missing 'name'")
    cls = estimator_class(name)
    return cls(validate(cls.Config, node, f"estimator '{name}'"))
