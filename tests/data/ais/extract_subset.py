"""Regenerate a recording's ``positions.csv.gz`` from its original file, and search it for cases.

Two recordings (``build_cases.RECORDINGS``; ``SOURCE.md`` beside each positions file):

- ``solent`` (``tests/data/ais``): ``docs/demos/SolentAIS_20160112_130211.csv`` of
  https://github.com/dstl/Stone-Soup (columns ``Time,MMSI,Latitude_degrees,
  Longitude_degrees,COG_degrees,SOG_knots``);
- ``nyharbor`` (``tests/data/ais_nyharbor``): ``NYHarbor_2020_06_30_first_hour.csv`` of the
  PyPI package ``tracktable-data`` 1.7.3.1 (US MarineCadastre CSV columns ``BaseDateTime,
  LON,LAT,MMSI,SOG,COG,Heading,VesselName,IMO,CallSign,VesselType,Status,Length,Width,Draft,
  Cargo,TranscieverClass,ETA``), given as that CSV or as the wheel that holds it.

Usage::

    python tests/data/ais/extract_subset.py ORIGINAL.csv            # writes positions.csv.gz
    python tests/data/ais/extract_subset.py ORIGINAL.csv --search   # prints a CASES table
    python tests/data/ais/extract_subset.py --recording nyharbor \
        tracktable_data-1.7.3.1-py3-none-any.whl [--search]

Conversion, Solent: ``Time`` (receiver time stamps, UTC, no zone in the file) becomes ISO-8601
with Z and milliseconds; ``COG_degrees`` = 360 (AIS "not available") becomes empty; exact
duplicate rows are dropped; nothing else is changed. The subset keeps, for every vessel used by
``build_cases.CASES`` (as own-ship or target), its reports within ``MARGIN_S`` of the windows
it is used in, sorted by MMSI then time.

Conversion, New York Harbor: ``BaseDateTime`` (UTC, whole seconds, no zone in the file) becomes
ISO-8601 with Z and milliseconds; ``SOG`` 102.3 (AIS "not available") becomes empty; ``COG``
is the AIS 12-bit course field (tenths of a degree) read as a *signed* number, so that courses
from 204.8 deg on appear as course - 409.6 (from -204.8 to -0.1): they are unwrapped (+409.6),
and 360.0 ("not available", -49.6 in the file) or more becomes empty; rows that repeat a
vessel's time stamp with the same position, speed and course (they differ only in fields not
kept) are kept once. Fishing vessels (``VesselType`` 30, and 1001-1002, the US fishing
codes, on any of their reports) are left out: fishing traffic is kept aside for an
independent check. The subset keeps every other vessel over the whole hour (the motion
statistics of ``motion_stats.py`` use them all; 90 kB gzipped), sorted by MMSI then time.

``--search`` scans the whole recording for cases meeting the rules of ``build_cases`` (the
recording's ``Rules``) and selects a set, deterministically:

1. windows start on every whole UTC minute and last ``Search.durations_s`` (20 or 25 min);
2. for each ordered pair (own-ship, target) and each target class, the window with the largest
   own-ship turn is kept (ties: the longer, then the earlier window);
3. steady cases (the scarce class) are considered before manoeuvring ones; within a class,
   each own-ship's best candidate (largest own-ship turn) comes first, then each one's second
   best, and so on (ties: larger own-ship turn, own MMSI, target MMSI);
4. a candidate is accepted while its unordered pair of vessels is not used yet, its own-ship
   has fewer than ``max_per_own`` cases, its target fewer than ``max_per_target`` cases as a
   target and its class fewer than ``max_per_kind`` cases (``SEARCH``, per recording);
5. the accepted cases are ordered by start time, then own MMSI, then target MMSI.
"""

import argparse
import hashlib
import io
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import build_cases as bc  # noqa: E402

MARGIN_S = 300.0
COLUMNS = ["mmsi", "timestamp_utc", "lat_deg", "lon_deg", "sog_kn", "cog_deg"]
NY_MEMBER = "tracktable_data/python_example_data/NYHarbor_2020_06_30_first_hour.csv"
NY_SHA256 = "5b81f49dae4063dca6170a9b96dfcf5d10d680edc1529bbe68170180b23a8329"
FISHING_TYPES = (30, 1001, 1002)


@dataclass(frozen=True)
class Search:
    """How ``--search`` picks a recording's cases (module docstring)."""

    durations_s: tuple[float, ...] = (1200.0, 1500.0)
    start_step_s: float = 60.0
    max_per_own: int = 4
    max_per_target: int = 5
    max_per_kind: int = 18


SEARCH = {"solent": Search(), "nyharbor": Search()}


def read_original(path, recording: str = "solent") -> pd.DataFrame:
    """The original file of ``recording`` as position reports (``COLUMNS`` plus ``t_s``)."""
    return {"solent": read_solent, "nyharbor": read_nyharbor}[bc.get_recording(recording).name](
        path)


def read_solent(path) -> pd.DataFrame:
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


def read_nyharbor_raw(path) -> pd.DataFrame:
    """``NYHarbor_2020_06_30_first_hour.csv`` as it is, from the CSV or from the wheel of
    ``tracktable-data`` 1.7.3.1; raises ``ValueError`` if its bytes are not the known ones."""
    path = Path(path)
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as whl:
            data = whl.read(NY_MEMBER)
    else:
        data = path.read_bytes()
    if hashlib.sha256(data).hexdigest() != NY_SHA256:
        raise ValueError(f"{path}: not NYHarbor_2020_06_30_first_hour.csv of tracktable-data "
                         f"1.7.3.1 (sha256 {NY_SHA256}); see tests/data/ais_nyharbor/SOURCE.md")
    return pd.read_csv(io.BytesIO(data), dtype={"BaseDateTime": str, "MMSI": np.int64})


def fishing_mmsis(raw: pd.DataFrame) -> set[int]:
    """MMSIs of the vessels whose ``VesselType`` is a fishing code on any report."""
    return set(raw.loc[raw["VesselType"].isin(FISHING_TYPES), "MMSI"].astype(int))


def read_nyharbor(path) -> pd.DataFrame:
    """The New York Harbor recording as position reports (``COLUMNS`` plus ``t_s``), fishing
    vessels left out (conversion in the module docstring)."""
    raw = read_nyharbor_raw(path)
    raw = raw[~raw["MMSI"].isin(fishing_mmsis(raw))]
    t_s = bc.to_seconds(raw["BaseDateTime"].to_numpy())  # no zone in the file: UTC
    sog = raw["SOG"].astype(float)
    cog = raw["COG"].astype(float)
    cog = np.round(cog.where(cog >= 0.0, cog + 409.6), 1)  # the 12-bit field read as signed
    df = pd.DataFrame({"mmsi": raw["MMSI"].to_numpy(), "timestamp_utc": bc.to_utc(t_s, 3),
                       "lat_deg": raw["LAT"].to_numpy(float),
                       "lon_deg": raw["LON"].to_numpy(float),
                       "sog_kn": sog.where(sog < 102.3).to_numpy(),
                       "cog_deg": cog.where(cog < 360.0).to_numpy(), "t_s": t_s})
    df = df.drop_duplicates(COLUMNS)
    return df.sort_values(["mmsi", "t_s"], kind="stable").reset_index(drop=True)


def type_group(vessel_type: float) -> str:
    """The group of a MarineCadastre ``VesselType`` code used in ``SOURCE.md``."""
    if not np.isfinite(vessel_type):
        return "no type given"
    t = int(vessel_type)
    if t in (31, 32, 52):
        return "tug/towing 31, 32, 52"
    for lo, name in ((60, "passenger 60-69"), (70, "cargo 70-79"), (80, "tanker 80-89")):
        if lo <= t <= lo + 9:
            return name
    return f"other ({t})"


def vessel_table(raw: pd.DataFrame, mmsis) -> pd.DataFrame:
    """Per type group: the vessels among ``mmsis`` and their reports in ``raw`` (the
    original MarineCadastre columns), largest first."""
    raw = raw[raw["MMSI"].isin(list(mmsis))]
    vtype = raw.groupby("MMSI")["VesselType"].max()  # NaN only where no report has a type
    groups = vtype.map(type_group)
    reports = raw.groupby("MMSI").size()
    table = pd.DataFrame({"vessels": groups.value_counts(),
                          "reports": reports.groupby(groups).sum()})
    return table.sort_values(["vessels", "reports"], ascending=False)


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


def search(tracks: dict[int, bc.Track], rules: bc.Rules = bc.SOLENT_RULES,
           how: Search = SEARCH["solent"]) -> pd.DataFrame:
    """Every (own-ship, target, window) meeting the case rules, one row each."""
    t_first = min(tr.t[0] for tr in tracks.values())
    t_last = max(tr.t[-1] for tr in tracks.values())
    starts = np.arange(np.ceil(t_first / 60.0) * 60.0, t_last, how.start_step_s)
    rows, kinds = [], {}  # kinds: a target's class per window, computed once
    for own in tracks.values():
        for dur in how.durations_s:
            for t0 in starts[starts + dur <= own.t[-1]]:
                if own.max_gap(t0, t0 + dur) > rules.max_gap_own_s:
                    continue
                m = bc.motion(own, t0, t0 + dur)
                if m.moving_frac < bc.MIN_OWN_MOVING_FRAC:
                    continue
                if not m.course_change_deg >= bc.MIN_OWN_TURN_DEG:
                    continue
                for tgt in tracks.values():
                    if (tgt.mmsi == own.mmsi
                            or tgt.max_gap(t0, t0 + dur) > rules.max_gap_target_s):
                        continue
                    key = (tgt.mmsi, t0, dur)
                    if key not in kinds:
                        kinds[key] = bc.classify(bc.motion(tgt, t0, t0 + dur), t0 + dur)
                    if kinds[key] is None:  # check_case would say not ok
                        continue
                    chk = bc.check_case(own, tgt, t0, dur, rules)
                    if chk["ok"]:
                        rows.append({"own_mmsi": own.mmsi, "target_mmsi": tgt.mmsi,
                                     "t0": t0, "duration_s": dur, **chk})
    return pd.DataFrame(rows)


def select(cand: pd.DataFrame, how: Search = SEARCH["solent"]) -> list[bc.CaseSpec]:
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
        if (pair in pairs or per_own.get(r.own_mmsi, 0) >= how.max_per_own
                or per_target.get(r.target_mmsi, 0) >= how.max_per_target
                or per_kind.get(r.kind, 0) >= how.max_per_kind):
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
    parser.add_argument("original", help="the recording's original file: "
                        "SolentAIS_20160112_130211.csv from Stone Soup (solent); "
                        "NYHarbor_2020_06_30_first_hour.csv or the tracktable-data 1.7.3.1 "
                        "wheel that holds it (nyharbor)")
    parser.add_argument("--recording", default="solent", choices=sorted(bc.RECORDINGS))
    parser.add_argument("--out", help="default: the recording's positions.csv.gz")
    parser.add_argument("--search", action="store_true", help="print a CASES table instead")
    args = parser.parse_args(argv)
    rec = bc.get_recording(args.recording)
    df = read_original(args.original, rec.name)
    if args.search:
        cand = search(bc.tracks_from(df, rec.rules), rec.rules, SEARCH[rec.name])
        specs = select(cand, SEARCH[rec.name])
        print(f"# {len(cand)} candidates; selected {len(specs)}")
        print("CASES: tuple[CaseSpec, ...] = (")
        for s in specs:
            print(f"    CaseSpec({s.own_mmsi}, {s.target_mmsi}, \"{s.start_utc}\", "
                  f"{s.duration_s:.0f}),")
        print(")")
        return 0
    # the Solent keeps the case vessels near their windows; New York all its vessels
    sub = subset(df, rec.cases) if rec.name == "solent" else df.loc[:, COLUMNS]
    sub[["lat_deg", "lon_deg"]] = sub[["lat_deg", "lon_deg"]].round(7)
    out = args.out or rec.positions_path
    sub.to_csv(out, index=False, lineterminator="\n",
               compression={"method": "gzip", "mtime": 0})
    print(f"wrote {len(sub)} reports of {sub['mmsi'].nunique()} vessels to {out}")
    if rec.name == "nyharbor":
        print(vessel_table(read_nyharbor_raw(args.original), sub["mmsi"].unique()).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
