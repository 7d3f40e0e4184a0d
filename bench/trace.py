"""The files one bearing passes, from a CSV to its table, counted by a trace: ``python
bench/trace.py [--rows N] [--json]`` (``make bench ARGS="--only trace"``;
``tests/test_trace.py`` holds ``docs/architecture.md``'s list to it).

It writes a recorded log of ``--rows`` bearings (600: one contact of a real-motion case,
``tests/data/ais``), runs ``python -m pipeline.table input=LOG`` in this process (the stages
in turn: ingest, estimate, aggregate; ``parallel=serial`` so that the shards run here too)
under ``sys.setprofile`` and records every call of a Python function of ``pipeline/`` or
``tma/`` made while a stage runs, leaving out what runs at import (a module's top level and
what it calls) and what the command does around its stages (Hydra's start, the error policy).
Per stage: the files, by layer (``cli``: ``pipeline/``; ``core``: ``tma/`` outside the
families; ``family``: ``tma/families/<name>/``), and the calls that cross a layer, each
distinct caller and callee function once: down (cli -> core -> family) and up (the family
using the core's I/O, or the core calling back into the CLI).
"""

import argparse
import json
import os
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
STAGES = {"ingest_stage": "ingest", "estimate_stage": "estimate",
          "aggregate_stage": "aggregate"}  # the stage functions of pipeline/
RANK = {"cli": 0, "core": 1, "family": 2}


def layer(path: str) -> str | None:
    """The layer of a file of this checkout (None: not ours)."""
    try:
        rel = Path(path).resolve().relative_to(REPO)
    except ValueError:
        return None
    parts = rel.parts
    if parts[0] == "pipeline":
        return "cli"
    if parts[0] != "tma":
        return None
    return "family" if parts[1:2] == ("families",) and len(parts) > 3 else "core"


def write_log(path: Path, rows: int) -> Path:
    """A real-motion navigation export of ``rows`` bearings (one contact)."""
    sys.path.insert(0, str(REPO / "tests" / "data" / "ais"))
    import build_cases

    exports, _ = build_cases.build_cases()
    export = exports["case_11"].loc[:, list(build_cases.EXPORT_COLUMNS)]
    export.iloc[:rows].to_csv(path, index=False)
    return path


class Tracer:
    """``sys.setprofile``'s hook: the calls made while a stage runs, not at import."""

    def __init__(self):
        self.stage = None
        self.files = defaultdict(set)  # stage -> relative paths
        self.edges = defaultdict(set)  # stage -> {(caller, callee, direction)}
        self.cache = {}

    def _ours(self, code):
        key = code.co_filename
        if key not in self.cache:
            found = layer(key)
            self.cache[key] = None if found is None else (
                found, str(Path(key).resolve().relative_to(REPO)))
        return self.cache[key]

    def __call__(self, frame, event, arg):
        if event == "return" and self.stage and frame.f_code.co_name in STAGES \
                and self._ours(frame.f_code) and self._ours(frame.f_code)[0] == "cli":
            self.stage = None
            return
        if event != "call":
            return
        code = frame.f_code
        ours = self._ours(code)
        if ours is None:
            return
        if code.co_name in STAGES and ours[0] == "cli":
            self.stage = STAGES[code.co_name]
        if self.stage is None or self._at_import(frame):
            return
        self.files[self.stage].add(ours[1])
        caller = frame.f_back
        while caller is not None and self._ours(caller.f_code) is None:
            caller = caller.f_back  # through the libraries between two of our functions
        if caller is None:
            return
        theirs = self._ours(caller.f_code)
        if theirs[0] != ours[0]:
            direction = "down" if RANK[ours[0]] > RANK[theirs[0]] else "up"
            self.edges[self.stage].add((f"{theirs[1]}:{caller.f_code.co_name}",
                                        f"{ours[1]}:{code.co_name}", direction))

    @staticmethod
    def _at_import(frame) -> bool:
        frame = frame.f_back
        while frame is not None:
            if frame.f_code.co_name == "<module>" and frame.f_back is not None:
                return True  # a module's top level, below the program's own
            frame = frame.f_back
        return False


def trace(rows: int = 600) -> dict:
    """``{stage: {"files": {layer: [paths]}, "down": [...], "up": [...]}}`` of one table."""
    work = Path(tempfile.mkdtemp(prefix="tma-trace-"))
    log = write_log(work / "log.csv", rows)
    os.environ["HYDRA_FULL_ERROR"] = "1"
    sys.argv = ["table", f"input={log}", f"paths.data_dir={work / 'data'}",
                f"paths.tables_dir={work / 'tables'}", "parallel=serial", "progress=false",
                f"hydra.run.dir={work / 'hydra'}"]
    from pipeline.table import main

    tracer = Tracer()
    sys.setprofile(tracer)
    try:
        main()
    finally:
        sys.setprofile(None)
    out = {}
    for stage in STAGES.values():
        files = defaultdict(list)
        for path in sorted(tracer.files[stage]):
            files[layer(REPO / path)].append(path)
        edges = sorted(tracer.edges[stage])
        out[stage] = {"files": dict(files),
                      "down": [f"{a} -> {b}" for a, b, d in edges if d == "down"],
                      "up": [f"{a} -> {b}" for a, b, d in edges if d == "up"]}
    return out


def summary(result: dict) -> str:
    lines, every = [], set()
    for stage, found in result.items():
        files = found["files"]
        every |= {p for paths in files.values() for p in paths}
        lines.append(f"{stage}: {sum(map(len, files.values()))} files ("
                     + ", ".join(f"{k} {len(v)}" for k, v in files.items())
                     + f"); calls across layers: {len(found['down'])} down, "
                     f"{len(found['up'])} up")
        for k, v in files.items():
            lines.append(f"  {k}: {' '.join(v)}")
        lines += [f"  down {e}" for e in found["down"]] + [f"  up   {e}" for e in found["up"]]
    lines.append(f"every stage: {len(every)} files")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=600)
    parser.add_argument("--json", action="store_true", help="the result as JSON on stdout")
    args = parser.parse_args()
    result = trace(args.rows)
    print(json.dumps(result) if args.json else summary(result))


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    main()
