"""Where and how the work runs: ``parallel`` (the engine: shard tasks in this process, in
local joblib workers or on Dask), ``forkserver`` (workers forked from a server that preloaded
their modules, ending with their command), ``cluster`` (a Dask scheduler or LocalCluster),
``worker_preload`` (what the server imports), ``jit`` (numba's compiled kernels and their
cache) and ``sharding`` (shards and their random streams).
"""
