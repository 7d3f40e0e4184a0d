"""Shards: how every family cuts its tracks into shards and seeds each shard's draws."""

import numpy as np


def n_shards(cfg) -> int:
    """Number of shards of ``cfg.n_tracks`` tracks in shards of ``cfg.shard_size``."""
    return -(-cfg.n_tracks // cfg.shard_size)


def shard_track_ids(cfg, shard_index: int) -> np.ndarray:
    """Track ids (int64) of shard ``shard_index``: consecutive, the last shard may be short."""
    first = shard_index * cfg.shard_size
    return np.arange(first, min(first + cfg.shard_size, cfg.n_tracks), dtype=np.int64)


def shard_rng(cfg, shard_index: int, stream: int | tuple[int, ...] | None = None
              ) -> np.random.Generator:
    """The shard's random stream, ``SeedSequence(seed, spawn_key=(shard,))``: a shard's draws
    depend neither on the other shards nor on the number of workers. ``stream``: one of the
    shard's further streams, ``spawn_key=(shard, stream)``, for draws added later (outliers,
    manoeuvres) that must leave the first stream's draws as they were; a tuple for a family
    of them (``(stream, k)``: ``spawn_key=(shard, stream, k)``, e.g. one per platform)."""
    key = ((shard_index,) if stream is None else (shard_index, *stream)
           if isinstance(stream, tuple) else (shard_index, stream))
    return np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=key))
