"""Numpy columns -> an Arrow table, without importing pandas.

``pyarrow.array`` (and so ``pa.table`` of a dict) imports pandas the first time it runs, to
ask whether its input is a pandas object: 0.26 s in every worker process, which writes
Parquet (truth, shard estimates) but never uses pandas. The columns tma writes are numpy
arrays of numbers, booleans or text, so they are wrapped here directly, numbers without a
copy, as the same Arrow types ``pa.array`` gives them (the Parquet bytes are the same);
anything else goes through ``pa.array``.
"""

import numpy as np
import pyarrow as pa

from tma.io.atomic import VerifiedPath

MAX_STRING_BYTES = 2**31 - 1  # 32-bit offsets: ``pa.string()``, as pa.array would type it


def column(values) -> pa.Array:
    """A 1-D numpy array (or sequence) as an Arrow array: integer and float dtypes as their
    own Arrow type, ``bool`` as ``bool_``, text (``str`` objects or a ``U`` dtype) as
    ``string``; NaN stays a value, never a null (as ``pa.array`` of numpy does)."""
    a = np.asarray(values)
    if a.ndim != 1:
        raise ValueError(f"a column must be 1-D, got shape {a.shape}")
    if a.dtype.kind in "iuf":
        a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("="))
        return pa.Array.from_buffers(pa.from_numpy_dtype(a.dtype), a.size,
                                     [None, pa.py_buffer(a)])
    if a.dtype.kind == "b":
        bits = np.packbits(a, bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), a.size, [None, pa.py_buffer(bits)])
    if a.dtype.kind in "OU":
        items = a.tolist()  # an empty object column has no type to find (pyarrow: null)
        if (items or a.dtype.kind == "U") and all(type(s) is str for s in items):
            encoded = [s.encode("utf-8") for s in items]
            offsets = np.zeros(len(encoded) + 1, dtype=np.int64)
            np.cumsum([len(b) for b in encoded], out=offsets[1:])
            if offsets[-1] <= MAX_STRING_BYTES:
                return pa.Array.from_buffers(
                    pa.string(), len(encoded),
                    [None, pa.py_buffer(offsets.astype(np.int32)), pa.py_buffer(b"".join(encoded))])
    return pa.array(a)  # anything else (None, dates, very long text): pyarrow's conversion


def table(columns: dict) -> pa.Table:
    """``pa.table(columns)`` for a dict of 1-D columns (``column``), without pandas."""
    return pa.Table.from_arrays([column(v) for v in columns.values()], names=list(columns))


def read_table(path) -> pa.Table:
    """One Parquet file as an Arrow table (from the checked bytes of a ``VerifiedPath``).
    ``pq.read_table`` reads through ``pyarrow.dataset`` and, the first time, imports it and
    pandas (0.25-0.35 s, on the main process's path between two stages); ``ParquetFile.read``
    gives the same table."""
    import pyarrow.parquet as pq

    verified = isinstance(path, VerifiedPath) and path.data is not None
    return pq.ParquetFile(pa.BufferReader(path.data) if verified else path).read()
