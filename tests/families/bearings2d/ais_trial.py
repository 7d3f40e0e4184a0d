"""A sea trial with the AIS of the ships around it, from the Solent recording of
``tests/data/ais`` (``SOURCE.md``): own-ship MMSI 235086588 takes bearings of two ships for
20 minutes from 13:33 UTC (``build_cases`` cases 16 and 17: the same own-ship and window),
labelled T1, T2 as a sonar would, with 0.5 deg noise. Its bearings come from
``build_cases`` (geodesic azimuths between positions interpolated in latitude/longitude),
independent of ``tma.ais``; the AIS files hold every vessel of the recording near that time,
as a receiver would log them:

- ``trial.csv``: the navigation export (timestamp_utc, latitude_deg, longitude_deg,
  bearing_deg, contact);
- ``trial_ais.csv``: decoded reports as Stone Soup's Solent file writes them (``Time`` without
  zone, ``MMSI``, ``Latitude_degrees``, ``Longitude_degrees``, ``COG_degrees``, ``SOG_knots``);
- ``trial_ais.nmea``: the same reports as raw ``!AIVDM`` sentences (pyais's encoder), each
  with a tag block time stamp, with two-part static messages (type 5) between them.

``TRUTH``: each contact's ship.
"""

import importlib.util
import sys
from pathlib import Path

import pandas as pd

AIS = Path(__file__).resolve().parents[2] / "data" / "ais"
CASES = (16, 17)  # build_cases.CASES numbers (1-based): own-ship 235086588, 13:33, 1200 s
OWN = 235086588
TRUTH = {"T1": 235031618, "T2": 247007000}
MARGIN_S = 300.0


def cases_module():
    spec = importlib.util.spec_from_file_location("ais_build_cases", AIS / "build_cases.py")
    module = sys.modules.get(spec.name)
    if module is None:
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
    return module


def trial_export() -> pd.DataFrame:
    """The trial's navigation export: one row per bearing of T1 and T2."""
    bc = cases_module()
    tracks = bc.tracks_from(bc.load_positions())
    frames = []
    for label, number in zip(TRUTH, CASES, strict=True):
        spec = bc.CASES[number - 1]
        assert spec.own_mmsi == OWN and spec.target_mmsi == TRUTH[label]
        df, _ = bc.make_case(number, spec, tracks, bc.SIGMA_DEG, bc.SEED)
        frames.append(df.assign(contact=label)[["timestamp_utc", "latitude_deg",
                                                "longitude_deg", "bearing_deg", "contact"]])
    return pd.concat(frames, ignore_index=True).sort_values(["timestamp_utc", "contact"],
                                                            kind="stable")


def ais_reports() -> pd.DataFrame:
    """Every report of the recording within ``MARGIN_S`` of the trial (all vessels)."""
    bc = cases_module()
    reports = bc.load_positions()
    spec = bc.CASES[CASES[0] - 1]
    t0 = float(bc.to_seconds(spec.start_utc)[0])
    near = (reports.t_s >= t0 - MARGIN_S) & (reports.t_s <= t0 + spec.duration_s + MARGIN_S)
    return reports[near].sort_values("t_s", kind="stable").reset_index(drop=True)


def write_ais_csv(path, reports: pd.DataFrame):
    """Decoded reports in Stone Soup's spelling (time without zone, as in its file)."""
    time = pd.to_datetime(reports.t_s * 1e9, utc=True).dt.strftime("%Y-%m-%d %H:%M:%S.%f")
    pd.DataFrame({"Time": time.str[:-3], "MMSI": reports.mmsi,
                  "Latitude_degrees": reports.lat_deg, "Longitude_degrees": reports.lon_deg,
                  "COG_degrees": reports.cog_deg.fillna(360.0),
                  "SOG_knots": reports.sog_kn}).to_csv(path, index=False)


def nmea_lines(reports: pd.DataFrame) -> list[str]:
    """The reports as tag-blocked ``!AIVDM`` sentences (type 1), a two-part type 5 of each
    vessel every 100 reports."""
    from pyais.encode import encode_dict

    lines = []
    for k, r in enumerate(reports.itertuples(index=False)):
        stamp = f"c:{r.t_s:.3f}"  # NMEA 4 tag block: receiver time, Unix s
        checksum = 0
        for ch in stamp:
            checksum ^= ord(ch)
        block = f"\\{stamp}*{checksum:02X}\\"
        (sentence,) = encode_dict({"type": 1, "mmsi": int(r.mmsi), "lat": float(r.lat_deg),
                                   "lon": float(r.lon_deg), "speed": float(r.sog_kn),
                                   "second": int(r.t_s) % 60}, talker_id="AI",
                                  sentence_type="VDM", radio_channel="AB"[k % 2])
        lines.append(block + sentence)
        if k % 100 == 0:
            for part in encode_dict({"type": 5, "mmsi": int(r.mmsi), "shipname": "TRIAL"},
                                    talker_id="AI", sentence_type="VDM", seq_id=k % 10):
                lines.append(block + part)
    return lines


def write_trial(d: Path) -> Path:
    """``trial.csv``, ``trial_ais.csv`` and ``trial_ais.nmea`` in ``d``."""
    trial_export().to_csv(d / "trial.csv", index=False)
    reports = ais_reports()
    write_ais_csv(d / "trial_ais.csv", reports)
    (d / "trial_ais.nmea").write_text("\n".join(nmea_lines(reports)) + "\n")
    return d
