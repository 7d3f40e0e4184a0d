"""Every option of every scenario and estimator, of ingest and of ``parallel``, from their
declarations (``tma.config.param``): ``python -m tma.options [NAME ...]`` (``make options``,
``make options ARGS=lm``, ``make options ARGS="ingest parallel"``) prints each key as the
command line sets it (``scenario.KEY=``, ``estimator.KEY=``, ingest's ``csv.delimiter=`` or
``sigma_deg=``, ``parallel.KEY=``), its default, the values it allows and what it means.
``ingest``: the reading options (``tma.sources.options``, with those each reader declares) and
the family's own settings (its ``ingest.Settings``), for each family that reads recorded logs;
``parallel``: where shards run (``tma.runtime.parallel.Engine``; ``conf/parallel/*.yaml`` are
presets of these keys)."""

import sys
from pathlib import Path

from tma.config import describe
from tma.errors import ConfigError
from tma.families import NAMES, estimator_class, estimator_names, family, reads_logs

GROUPS = ("ingest", "parallel")
PRESETS = Path(__file__).resolve().parents[1] / "conf" / "parallel"  # in a checkout


def block(header: str, rows) -> str:
    """``rows`` of ``(key, default, allowed, doc)`` under ``header``, as aligned text."""
    rows = list(rows)
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = [header] + [f"  {k:{widths[0]}}  {d:{widths[1]}}  {a:{widths[2]}}  {doc}".rstrip()
                        for k, d, a, doc in rows]
    return "\n".join(lines)


def table(kind: str, name: str, schema) -> str:
    """The options of one scenario (``kind`` scenario) or estimator, as aligned text."""
    rows = [(f"{kind}.{key}", default, allowed, doc)
            for key, default, allowed, doc in describe(schema) if key not in ("family", "name")]
    header = f"{kind}={name}" + (f" ({family(name).name} scenario)" if kind == "scenario" else
                                 f" ({estimator_class(name).family} estimator)")
    return block(header, rows)


def ingest_families() -> list[str]:
    return [name for name in NAMES if reads_logs(name)]


def ingest_rows(name: str) -> list[tuple[str, str, str, str]]:
    """The ingest options of family ``name``: its settings, then the reading options."""
    from tma.ais.options import TruthOptions
    from tma.sources.options import options_schema

    reader = family(name).ingest
    return (describe(reader.Settings) + describe(options_schema(reader.OBSERVATION))
            + describe(TruthOptions, "truth."))


def ingest_tables() -> list[str]:
    return [block(f"ingest family={name} (python -m pipeline.ingest input=LOG KEY=VALUE ...)",
                  ingest_rows(name)) for name in ingest_families()]


def parallel_rows() -> list[tuple[str, str, str, str]]:
    from tma.runtime.parallel import Engine

    return describe(Engine, "parallel.")


def presets() -> str:
    """``default: engine=joblib n_jobs=2; ...``: what each preset of ``conf/parallel`` sets."""
    import yaml

    return "; ".join(f"{path.stem}: " + " ".join(
        f"{k}={yaml.safe_dump(v, default_flow_style=True).splitlines()[0]}"
        for k, v in (yaml.safe_load(path.read_text()) or {}).items())
        for path in sorted(PRESETS.glob("*.yaml")))


def parallel_table() -> str:
    header = ("parallel (where shards run; parallel=NAME chooses a preset, parallel.KEY=VALUE "
              "sets a key)")
    text = presets() if PRESETS.is_dir() else ""
    return block(header + (f"\n  presets: {text}" if text else ""), parallel_rows())


def main(argv: list[str]) -> int:
    names = argv or [*NAMES, *estimator_names(), *GROUPS]
    blocks = []
    for name in names:
        if name in NAMES:
            blocks.append(table("scenario", name, family(name).scenario.Config))
        elif name in estimator_names():
            blocks.append(table("estimator", name, estimator_class(name).Config))
        elif name == "ingest":
            blocks += ingest_tables()
        elif name == "parallel":
            blocks.append(parallel_table())
        else:
            known = ", ".join([*NAMES, *estimator_names(), *GROUPS])
            message = f"no scenario or estimator {name!r}, nor ingest or parallel (known: {known})"
            print(f"error: {ConfigError(message)}", file=sys.stderr)
            return 2
    print("\n\n".join(blocks))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
