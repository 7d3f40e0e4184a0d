"""``tma.io.arrow``: numpy columns -> Arrow without pandas, checked against pyarrow's own
conversion (the same table, the same Parquet bytes) and in a fresh process (no pandas)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tma.io import arrow
from tma.io.atomic import write_parquet_atomic

REPO = Path(__file__).resolve().parents[1]
DTYPES = [np.float64, np.float32, np.int64, np.int32, np.uint8, np.bool_]


@st.composite
def columns(draw):
    n = draw(st.integers(0, 40))
    out = {}
    for i, dtype in enumerate(draw(st.lists(st.sampled_from(DTYPES), min_size=1, max_size=5))):
        values = draw(hnp.arrays(dtype, n))
        if draw(st.booleans()) and n:  # a strided view, as a slice of a bigger array gives
            values = np.repeat(values, 2)[::2]
        out[f"c{i}"] = values
    if draw(st.booleans()):
        text = st.text(st.characters(blacklist_categories=("Cs",)), max_size=6)
        out["label"] = np.array(draw(st.lists(text, min_size=n, max_size=n)), dtype=object)
    return out


def _parquet_bytes(table: pa.Table, path: Path) -> bytes:
    pq.write_table(table, path, compression="zstd")
    return path.read_bytes()


@settings(max_examples=60, deadline=None)
@given(columns())
def test_a_table_is_what_pyarrow_makes_of_the_same_columns(tmp_path_factory, cols):
    ours, theirs = arrow.table(cols), pa.table(cols)
    assert ours.schema == theirs.schema
    for name in cols:  # bit for bit: NaN payloads and -0.0 kept, no value turned into a null
        a, b = ours[name].combine_chunks(), theirs[name].combine_chunks()
        assert a.null_count == b.null_count == 0
        if pa.types.is_floating(a.type) or pa.types.is_integer(a.type):
            assert a.to_numpy().tobytes() == b.to_numpy().tobytes() == cols[name].tobytes()
        else:
            assert a.to_pylist() == b.to_pylist() == cols[name].tolist()
    tmp = tmp_path_factory.mktemp("arrow")
    assert _parquet_bytes(ours, tmp / "ours.parquet") == _parquet_bytes(theirs, tmp / "b.parquet")


def test_other_columns_go_through_pyarrow():
    mixed = np.array(["ok", None], dtype=object)
    assert arrow.column(mixed).to_pylist() == ["ok", None]
    assert arrow.column(np.array(["a", "bé"])).type == pa.string()  # a numpy U dtype
    with pytest.raises(ValueError, match="1-D"):
        arrow.column(np.zeros((2, 2)))


def test_read_table_is_pyarrows_read_table(tmp_path):
    table = pa.table({"x": np.arange(5.0), "s": np.array(list("abcde"), dtype=object)})
    pq.write_table(table, tmp_path / "t.parquet")
    assert arrow.read_table(tmp_path / "t.parquet").equals(pq.read_table(tmp_path / "t.parquet"),
                                                           check_metadata=True)


def test_writing_and_reading_parquet_imports_no_pandas(tmp_path):
    code = f"""
import sys, numpy as np
from tma.io import arrow
from tma.io.atomic import write_parquet_atomic
table = arrow.table({{"x": np.arange(3.0), "ok": np.array([True, False, True]),
                     "status": np.array(["ok", "poor_fit", "ok"], dtype=object)}})
write_parquet_atomic(r"{tmp_path / 't.parquet'}", table)
assert arrow.read_table(r"{tmp_path / 't.parquet'}").num_rows == 3
print("pandas" in sys.modules, "pyarrow.dataset" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["False", "False"]


def test_float_columns_are_stored_plain_and_the_others_by_dictionary(tmp_path):
    """Dictionary pages pay off for repeated values (ids, flags, status), never for floats."""
    n = 5000
    table = arrow.table({"track_id": np.arange(n) % 7, "x_m": np.random.default_rng(0).random(n),
                         "status": np.array(["ok", "poor_fit"] * (n // 2), dtype=object)})
    write_parquet_atomic(tmp_path / "t.parquet", table)
    meta = pq.ParquetFile(tmp_path / "t.parquet").metadata.row_group(0)
    encodings = {meta.column(i).path_in_schema: set(meta.column(i).encodings)
                 for i in range(meta.num_columns)}
    assert not any("DICTIONARY" in e for e in encodings["x_m"])
    assert any("DICTIONARY" in e for e in encodings["track_id"])
    assert any("DICTIONARY" in e for e in encodings["status"])
    assert pq.read_table(tmp_path / "t.parquet").equals(table)
