"""Every option of every scenario and estimator, from their declarations (``tma.config.param``):
``python -m tma.options [NAME ...]`` (``make options``, ``make options ARGS=lm``) prints each
key as the command line sets it (``scenario.KEY=`` / ``estimator.KEY=``), its default, the
values it allows and what it means."""

import sys

from tma.config import describe
from tma.errors import ConfigError
from tma.families import NAMES, estimator_class, estimator_names, family


def table(kind: str, name: str, schema) -> str:
    """The options of one scenario (``kind`` scenario) or estimator, as aligned text."""
    rows = [(f"{kind}.{key}", default, allowed, doc)
            for key, default, allowed, doc in describe(schema) if key not in ("family", "name")]
    header = f"{kind}={name}" + (f" ({family(name).name} scenario)" if kind == "scenario" else
                                 f" ({estimator_class(name).family} estimator)")
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    lines = [header] + [f"  {k:{widths[0]}}  {d:{widths[1]}}  {a:{widths[2]}}  {doc}".rstrip()
                        for k, d, a, doc in rows]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    names = argv or [*NAMES, *estimator_names()]
    blocks = []
    for name in names:
        if name in NAMES:
            blocks.append(table("scenario", name, family(name).scenario.Config))
        elif name in estimator_names():
            blocks.append(table("estimator", name, estimator_class(name).Config))
        else:
            known = ", ".join([*NAMES, *estimator_names()])
            print(f"error: {ConfigError(f'no scenario or estimator {name!r} (known: {known})')}",
                  file=sys.stderr)
            return 2
    print("\n\n".join(blocks))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
