"""Regenerate ``positions.csv.gz`` from the original Stone Soup Solent AIS file.

The original is ``docs/demos/SolentAIS_20160112_130211.csv`` of https://github.com/dstl/Stone-Soup
(columns ``Time,MMSI,Latitude_degrees,Longitude_degrees,COG_degrees,SOG_knots``; see
``SOURCE.md``). Usage::

    python tests/data/ais/extract_subset.py ORIGINAL.csv            # writes positions.csv.gz
    python tests/data/ais/extract_subset.py ORIGINAL.csv --search   # prints a CASES table

Conversion: ``Time`` (receiver time stamps, UTC, no zone in the file) becomes ISO-8601 with Z
and milliseconds; ``COG_degrees`` = 360 (AIS "not available") becomes empty; exact duplicate
rows are dropped; nothing else is changed. The subset keeps, for every vessel used by
``build_cases.CASES`` (as own-ship or target), its reports within ``MARGIN_S`` of the windows
it is used in, sorted by MMSI then time.

``--search`` scans the whole recording for cases meeting the rules of ``build_cases`` and
selects a set, deterministically:

1. windows start on every whole UTC minute and last ``DURATIONS_S`` (20 or 25 min);
2. for each ordered pair (own-ship, target) and each target class, the window with the largest
   own-ship turn is kept (ties: the longer, then the earlier window);
3. steady cases (the scarce class) are considered before manoeuvring ones; within a class,
   each own-ship's best candidate (largest own-ship turn) comes first, then each one's second
   best, and so on (ties: larger own-ship turn, own MMSI, target MMSI);
4. a candidate is accepted while its unordered pair of vessels is not used yet, its own-ship
   has fewer than ``MAX_PER_OWN`` cases, its target fewer than ``MAX_PER_TARGET`` cases as a
   target and its class fewer than ``MAX_PER_KIND`` cases;
5. the accepted cases are ordered by start time, then own MMSI, then target MMSI.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import build_cases as bc  # noqa: E402

MARGIN_S = 300.0
DURATIONS_S = (1200.0, 1500.0)
START_STEP_S = 60.0
MAX_PER_OWN = 4
MAX_PER_TARGET = 5
MAX_PER_KIND = 18
COLUMNS = ["mmsi", "timestamp_utc", "lat_deg", "lon_deg", "sog_kn", "cog_deg"]


def read_original(path) -> pd.DataFrame:
    """The original Stone Soup CSV as position reports (``COLUMNS`` plus ``t_s``)."""
    raw = pd.read_csv(path, dtype={"Time": str, "MMSI": np.int64}).drop_duplicates()
    t_s = bc.to_seconds(raw["Time"].to_numpy())  # no zone in the file: taken as UTC
    cog = raw["COG_degrees"].astype(float)
    df = pd.DataFrame({"mmsi": raw["MMSI"].to_numpy(), "timestamp_utc": bc.to_utc(t_s, 3),
                       "lat_deg": raw["Latitude_degrees"].to_numpy(float),
                       "lon_deg": raw["Longitude_degrees"].to_numpy(float),
                       "sog_kn": raw["SOG_knots"].to_numpy(float),
                       "cog_deg": cog.where(cog < 360.0).to_numpy(), "t_s": t_s})
    return df.sort_values(["mmsi", "t_s"], kind="stable").reset_index(drop=True)


def subset(df: pd.DataFrame, cases=bc.CASES) -> pd.DataFrame:
    """The reports of the vessels used by ``cases``, within ``MARGIN_S`` of their windows."""
    keep = np.zeros(len(df), dtype=bool)
    for spec in cases:
        t0 = float(bc.to_seconds(spec.start_utc)[0])
        t1 = t0 + spec.duration_s
        for mmsi in (spec.own_mmsi, spec.target_mmsi):
            keep |= ((df["mmsi"] == mmsi) & (df["t_s"] >= t0 - MARGIN_S)
                     & (df["t_s"] <= t1 + MARGIN_S)).to_numpy()
    return df.loc[keep, COLUMNS].reset_index(drop=True)


def search(tracks: dict[int, bc.Track]) -> pd.DataFrame:
    """Every (own-ship, target, window) meeting the case rules, one row each."""
    t_first = min(tr.t[0] for tr in tracks.values())
    t_last = max(tr.t[-1] for tr in tracks.values())
    starts = np.arange(np.ceil(t_first / 60.0) * 60.0, t_last, START_STEP_S)
    rows = []
    for own in tracks.values():
        for dur in DURATIONS_S:
            for t0 in starts[starts + dur <= own.t[-1]]:
                if own.max_gap(t0, t0 + dur) > bc.MAX_GAP_OWN_S:
                    continue
                m = bc.motion(own, t0, t0 + dur)
                if m.moving_frac < bc.MIN_OWN_MOVING_FRAC:
                    continue
                if not m.course_change_deg >= bc.MIN_OWN_TURN_DEG:
                    continue
                for tgt in tracks.values():
                    if tgt.mmsi == own.mmsi or tgt.max_gap(t0, t0 + dur) > bc.MAX_GAP_TARGET_S:
                        continue
                    chk = bc.check_case(own, tgt, t0, dur)
                    if chk["ok"]:
                        rows.append({"own_mmsi": own.mmsi, "target_mmsi": tgt.mmsi,
                                     "t0": t0, "duration_s": dur, **chk})
    return pd.DataFrame(rows)


def select(cand: pd.DataFrame) -> list[bc.CaseSpec]:
    """Pick the cases from ``search``'s candidates (policy in the module docstring)."""
    cand = cand.sort_values(["own_mmsi", "target_mmsi", "kind", "own_turn_deg", "duration_s",
                             "t0"], ascending=[True, True, True, False, False, True])
    best = cand.groupby(["own_mmsi", "target_mmsi", "kind"], sort=False).head(1).copy()
    best["kind_order"] = (best["kind"] != "steady").astype(int)  # the scarce class first
    best = best.sort_values(["kind_order", "own_mmsi", "own_turn_deg", "target_mmsi", "t0"],
                            ascending=[True, True, False, True, True])
    best["rank"] = best.groupby(["kind_order", "own_mmsi"]).cumcount()
    best = best.sort_values(["kind_order", "rank", "own_turn_deg", "own_mmsi", "target_mmsi"],
                            ascending=[True, True, False, True, True])
    pairs, per_own, per_target, per_kind, chosen = set(), {}, {}, {}, []
    for r in best.itertuples():
        pair = frozenset((r.own_mmsi, r.target_mmsi))
        if (pair in pairs or per_own.get(r.own_mmsi, 0) >= MAX_PER_OWN
                or per_target.get(r.target_mmsi, 0) >= MAX_PER_TARGET
                or per_kind.get(r.kind, 0) >= MAX_PER_KIND):
            continue
        pairs.add(pair)
        per_own[r.own_mmsi] = per_own.get(r.own_mmsi, 0) + 1
        per_target[r.target_mmsi] = per_target.get(r.target_mmsi, 0) + 1
        per_kind[r.kind] = per_kind.get(r.kind, 0) + 1
        chosen.append(r)
    chosen.sort(key=lambda r: (r.t0, r.own_mmsi, r.target_mmsi))
    return [bc.CaseSpec(int(r.own_mmsi), int(r.target_mmsi), bc.to_utc(r.t0)[0],
                        float(r.duration_s)) for r in chosen]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("original", help="SolentAIS_20160112_130211.csv from Stone Soup")
    parser.add_argument("--out", default=str(HERE / "positions.csv.gz"))
    parser.add_argument("--search", action="store_true", help="print a CASES table instead")
    args = parser.parse_args(argv)
    df = read_original(args.original)
    if args.search:
        cand = search(bc.tracks_from(df))
        specs = select(cand)
        print(f"# {len(cand)} candidates; selected {len(specs)}")
        print("CASES: tuple[CaseSpec, ...] = (")
        for s in specs:
            print(f"    CaseSpec({s.own_mmsi}, {s.target_mmsi}, \"{s.start_utc}\", "
                  f"{s.duration_s:.0f}),")
        print(")")
        return 0
    sub = subset(df)
    sub[["lat_deg", "lon_deg"]] = sub[["lat_deg", "lon_deg"]].round(7)
    sub.to_csv(args.out, index=False, lineterminator="\n",
               compression={"method": "gzip", "mtime": 0})
    print(f"wrote {len(sub)} reports of {sub['mmsi'].nunique()} vessels to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
