"""Thin Hydra entry points, one verb each: ``python -m pipeline.<verb>``."""

from tma.families import register_configs

register_configs()  # scenario/* and estimator/* from the Config dataclasses, before Hydra composes
