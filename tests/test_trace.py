"""``docs/architecture.md`` lists the files one bearing really passes, from a CSV to its table:
the table "One bearing, from a CSV to the table" is what a trace of the command counts
(``bench/trace.py``: every function of ``pipeline/`` and ``tma/`` called while a stage runs),
stage by stage and layer by layer, with its totals; and the way down is once per stage (one
call from the CLI into the core)."""

import json
import re
import subprocess
import sys

from tests.conftest import REPO

PREFIX = {"cli": "pipeline/", "core": "tma/", "family": "tma/families/bearings2d/"}


def _documented() -> tuple[dict, str]:
    text = (REPO / "docs" / "architecture.md").read_text()
    section = text.split("### One bearing, from a CSV to the table", 1)[1].split("\n## ", 1)[0]
    table = {}
    for row in re.findall(r"^\| (ingest|estimate|aggregate) \|(.*)\|$", section, re.M):
        stage, cells = row[0], [c.strip() for c in row[1].split("|")]
        table[stage] = {layer: sorted(PREFIX[layer] + name for name in re.findall(r"`([^`]+)`", c))
                        for layer, c in zip(PREFIX, cells, strict=True)}
    return table, section


def test_the_documented_files_are_those_a_trace_counts():
    proc = subprocess.run([sys.executable, "bench/trace.py", "--json"], cwd=REPO,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    traced = json.loads(proc.stdout.strip().splitlines()[-1])
    documented, prose = _documented()
    assert documented == {stage: {layer: found["files"].get(layer, []) for layer in PREFIX}
                          for stage, found in traced.items()}, (
        "docs/architecture.md's table is not what python bench/trace.py counts")
    every = {p for found in traced.values() for files in found["files"].values() for p in files}
    per_layer = [len({p for f in traced.values() for p in f["files"].get(layer, [])})
                 for layer in PREFIX]
    per_stage = [sum(map(len, f["files"].values())) for f in traced.values()]
    assert (f"{len(every)} files in all ({' + '.join(map(str, per_layer))}; "
            f"{', '.join(map(str, per_stage[:-1]))} and {per_stage[-1]} per stage)") in \
        " ".join(prose.split())
    for stage, found in traced.items():  # the CLI goes down into the core once per stage
        cli_down = [e for e in found["down"] if e.startswith("pipeline/")]
        assert len(cli_down) == 1 and "tma/plan/command.py:run_" in cli_down[0], (stage,
                                                                                 cli_down)
