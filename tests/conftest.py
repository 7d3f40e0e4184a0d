"""Shared fixtures: Hydra compose against the repo's conf/, small datasets in tmp dirs."""

import contextlib
import importlib
import io
import logging
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from pipeline._common import CONF_DIR

REPO = Path(__file__).resolve().parents[1]
SMALL = ["scenario.n_tracks=60", "scenario.shard_size=25", "progress=false"]


def compose_cfg(overrides=(), config_name="config", **kwargs):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(config_name=config_name, overrides=list(overrides), **kwargs)


def run_cli(verb, *overrides, check=True, cwd=REPO, warnings=False):
    """Run ``python -m pipeline.<verb>`` in a subprocess; returns the CompletedProcess.
    ``warnings``: Python's default filters, as a user runs it (else silenced)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    if not warnings:
        env["PYTHONWARNINGS"] = "ignore"
    proc = subprocess.run([sys.executable, "-m", f"pipeline.{verb}", *overrides], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"pipeline.{verb} failed:\n{proc.stdout}\n{proc.stderr}")
    return proc


def run_stage_here(verb, *overrides, check=True):
    """Run ``pipeline.<verb>`` with these command-line overrides inside this process: the same
    Hydra entry point, stage guard and exit status as ``run_cli`` without a new interpreter
    (about 1 s each). Returns a CompletedProcess with the exit status and the captured
    stdout/stderr. Cases that need a real process (signals, mount namespaces, the launcher,
    ``__main__``) use ``run_cli``."""
    main = importlib.import_module(f"pipeline.{verb}").main
    root = logging.getLogger()
    saved = root.handlers[:], root.level, logging.raiseExceptions, sys.argv
    out, err, status = io.StringIO(), io.StringIO(), 0
    sys.argv = [f"pipeline/{verb}.py", *overrides]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
                warnings.catch_warnings():
            warnings.simplefilter("ignore")  # as PYTHONWARNINGS=ignore in run_cli
            try:
                main()
            except SystemExit as exc:
                status = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    finally:
        for handler in root.handlers:
            if handler not in saved[0]:
                handler.close()
        root.handlers[:], (root.level, logging.raiseExceptions, sys.argv) = saved[0], saved[1:]
        GlobalHydra.instance().clear()
    proc = subprocess.CompletedProcess(sys.argv, status, out.getvalue(), err.getvalue())
    if check and status != 0:
        raise AssertionError(f"pipeline.{verb} failed:\n{proc.stdout}\n{proc.stderr}")
    return proc


@pytest.fixture
def paths(tmp_path):
    return data_paths(tmp_path)


def data_paths(root) -> list[str]:
    """The overrides that put a command's data and tables under ``root``."""
    return [f"paths.data_dir={root / 'data'}", f"paths.tables_dir={root / 'tables'}"]


def plain_messages(path, topics=None) -> list:
    """``(channel, message, fields)`` of an MCAP file as a plain MCAP reader decodes it,
    without tma's code: protobuf with mcap-protobuf-support (the schema embedded in the
    file), JSON with the json module. ``fields``: a dict (repeated fields as lists)."""
    import json

    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message in reader.iter_messages(topics=topics, log_time_order=True):
            if channel.message_encoding == "json":
                fields = json.loads(message.data)
            else:
                schema = reader.get_summary().schemas[channel.schema_id]
                decoded = DecoderFactory().decoder_for("protobuf", schema)(message.data)
                fields = {d.name: (list(getattr(decoded, d.name)) if d.is_repeated
                                   else getattr(decoded, d.name))
                          for d in decoded.DESCRIPTOR.fields}
            out.append((channel, message, fields))
    return out


def proto_message_class(schema_name: str):
    """protobuf's own message class of a tma schema's protobuf twin, built by protobuf from
    the FileDescriptorSet tma embeds in its logs."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    from tma.io.proto_columns import proto_schema

    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(
            proto_schema(schema_name).descriptor_set).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def once_per_run(tmp_path_factory, name: str, compute):
    """``compute()``'s result, computed once per test run whatever the pytest-xdist workers:
    the first worker to ask computes it and pickles it under the run's shared base
    temporary directory (under a lock), the others read it. (``xdist_group`` marks would
    keep such tests on one worker, but pytest 9.2 drops the group from the node ids
    xdist schedules by, pytest-dev/pytest-xdist#1386: they spread as if unmarked.)"""
    import fcntl
    import pickle

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):  # (each worker's base is one per run's child)
        root = root.parent
    path = root / f"once-{name}.pickle"
    with open(root / f"once-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if path.exists():
            return pickle.loads(path.read_bytes())
        value = compute()
        path.write_bytes(pickle.dumps(value))
        return value
