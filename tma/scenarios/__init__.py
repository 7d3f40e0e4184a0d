"""Scenario families: each module declares a ``Config`` dataclass and simulates one shard.

A scenario module provides ``FAMILY``, ``Config`` (with ``n_tracks``, ``shard_size``,
``seed``), ``label(cfg)`` (short human tag used in dataset names) and
``simulate_shard(cfg, index) -> (log, truth_table or None)``; shards are cut and seeded by the
helpers below, the same for every family.
"""

import importlib

import numpy as np

from tma.config import to_plain, validate
from tma.errors import ConfigError
from tma.io.atomic import sha256_json

SCENARIO_MODULES = {
    "bearings2d": "tma.scenarios.bearings2d",
    "ranges2d": "tma.scenarios.ranges2d",
    "radar2d": "tma.scenarios.radar2d",
    "bearing_doppler3d": "tma.scenarios.bearing_doppler3d",
}


def n_shards(cfg) -> int:
    """Number of shards of ``cfg.n_tracks`` tracks in shards of ``cfg.shard_size``."""
    return -(-cfg.n_tracks // cfg.shard_size)


def shard_track_ids(cfg, shard_index: int) -> np.ndarray:
    """Track ids (int64) of shard ``shard_index``: consecutive, the last shard may be short."""
    first = shard_index * cfg.shard_size
    return np.arange(first, min(first + cfg.shard_size, cfg.n_tracks), dtype=np.int64)


def shard_rng(cfg, shard_index: int) -> np.random.Generator:
    """The shard's random stream, ``SeedSequence(seed, spawn_key=(shard,))``: a shard's draws
    depend neither on the other shards nor on the number of workers."""
    return np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(shard_index,)))


def scenario_module(family: str):
    """The scenario module of ``family``; a clear error for unknown names."""
    if family not in SCENARIO_MODULES:
        known = ", ".join(sorted(SCENARIO_MODULES))
        raise ConfigError(f"unknown scenario family '{family}' (known: {known})")
    return importlib.import_module(SCENARIO_MODULES[family])


def load_scenario(node):
    """Validate a scenario config node; return ``(module, config dataclass instance)``."""
    family = node.get("family") if node is not None else None
    if family is None:
        raise ConfigError("scenario: missing 'family'")
    module = scenario_module(family)
    return module, validate(module.Config, node, f"scenario '{family}'")


def dataset_name(module, cfg) -> str:
    """Directory name of the dataset a scenario config produces: family, label, config hash."""
    return f"{module.FAMILY}-{module.label(cfg)}-{sha256_json(to_plain(cfg))[:10]}"
