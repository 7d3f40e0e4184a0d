"""The ``tma`` command, installed by ``pip install`` (``[project.scripts]``): ``tma <verb>
[overrides]`` runs the Hydra app of ``python -m pipeline.<verb>``, the same config, bytes and
messages (``tma table input=log.csv``, ``tma ingest nav.csv``, ``tma simulate
scenario.sigma_deg=0.5``); ``tma --help`` lists the verbs, ``tma <verb> --help`` is Hydra's
help of that app."""

import difflib
import importlib
import sys

from pipeline import VERBS

WHAT = {"table": "simulate (or ingest input=LOG), estimate and aggregate in one process",
        "simulate": "scenario configs -> datasets (data/datasets/)",
        "ingest": "a recorded log (CSV, NMEA, MCAP) -> a dataset",
        "estimate": "datasets + estimator configs -> runs (data/runs/)",
        "aggregate": "runs -> metrics and tables (tables/)"}
USAGE = ("usage: tma <verb> [overrides]  (the same as python -m pipeline.<verb> [overrides])\n\n"
         "verbs:\n" + "".join(f"  {verb:<10} {WHAT[verb]}\n" for verb in VERBS)
         + "\ntma <verb> --help shows the verb's config and options; every option: "
           "python -m tma.options")


def main(argv: list[str] | None = None) -> int:
    """Run ``tma <verb> [overrides]`` (``argv``: the arguments after ``tma``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["-h"], ["--help"], ["help"]):
        print(USAGE)
        return 0
    if not argv:
        print(f"error: tma needs a verb: {', '.join(VERBS[:-1])} or {VERBS[-1]} (tma --help "
              "says what each does)", file=sys.stderr)
        return 2
    verb, rest = argv[0], argv[1:]
    if verb not in VERBS:
        near = difflib.get_close_matches(verb, VERBS, n=1)
        print(f"error: tma {verb}: no verb '{verb}' ("
              + (f"nearest: {near[0]}" if near else f"verbs: {', '.join(VERBS)}")
              + "; tma --help lists them)", file=sys.stderr)
        return 2
    sys.argv = [sys.argv[0], *rest]  # what the verb's Hydra app reads
    importlib.import_module(f"pipeline.{verb}").main()
    return 0


if __name__ == "__main__":
    sys.exit(main())
