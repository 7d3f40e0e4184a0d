"""Writes the small trial files the README's "Score a trial against AIS" runs (issue 38),
from the Solent trial of ``tests/families/bearings2d/ais_trial.py`` (itself from the Stone
Soup recording of ``tests/data/ais``, ``SOURCE.md``), as other exports write them:

- ``ais_export.csv``: the AIS of own-ship, its two contacts' ships and the two other ships
  nearest them, every report at least 10 s after the last kept, as a Spanish fishing-fleet
  export writes it: ``Fecha_Posicion;Mmsi;Latitud_decimal;Longitud_decimal;Sog``, ``;``
  between fields, a decimal comma, UTC times day first with a two-digit year
  (``12-01-16 13:28:00``), speed in knots;
- ``bearings_local.csv``: the trial's bearings as a sonar alone logs them, on a clock set to
  Madrid time (CET, UTC+1, in January): ``Hora,Contacto,Demora`` (``12/01/2016 14:33:00``),
  no own-ship;
- ``campaign/leg1.csv``, ``campaign/leg2.csv``: the same log cut into its first and last
  10 minutes, a campaign of two logs.

Run ``python tests/data/trials/build.py`` from the repository to write them again;
``tests/test_trials.py`` checks that they are what it writes.
"""

import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
OTHERS = 2  # ships beside own-ship and the contacts' two, to be told apart by the bearings
MIN_INTERVAL_S = 10.0


def _thinned(reports: pd.DataFrame) -> pd.DataFrame:
    keep, last = [], {}
    for k, r in enumerate(reports.itertuples(index=False)):
        if r.t_s - last.get(r.mmsi, -np.inf) >= MIN_INTERVAL_S:
            keep.append(k)
            last[r.mmsi] = r.t_s
    return reports.iloc[keep]


def files() -> dict[str, str]:
    """``{relative path: text}`` of every file."""
    sys.path.insert(0, str(HERE.parents[2]))
    from tests.families.bearings2d import ais_trial

    reports = ais_trial.ais_reports()
    trial = ais_trial.trial_export()
    wanted = [ais_trial.OWN, *ais_trial.TRUTH.values()]
    centre = reports[reports.mmsi.isin(wanted)][["lat_deg", "lon_deg"]].mean()
    distance = (reports.assign(d=np.hypot(reports.lat_deg - centre.lat_deg,
                                          (reports.lon_deg - centre.lon_deg) * 0.63))
                .groupby("mmsi").d.min().drop(wanted).sort_values())
    ships = reports[reports.mmsi.isin(wanted + list(distance.index[:OTHERS]))]
    ships = _thinned(ships)
    utc = pd.to_datetime(np.round(ships.t_s) * 1e9, utc=True)
    export = pd.DataFrame({"Fecha_Posicion": utc.dt.strftime("%d-%m-%y %H:%M:%S"),
                           "Mmsi": ships.mmsi, "Latitud_decimal": ships.lat_deg.round(7),
                           "Longitud_decimal": ships.lon_deg.round(7),
                           "Sog": ships.sog_kn.round(1)})
    out = {"ais_export.csv": export.to_csv(sep=";", decimal=",", index=False)}
    local = pd.to_datetime(trial.timestamp_utc, utc=True).dt.tz_convert("Europe/Madrid")
    log = pd.DataFrame({"Hora": local.dt.strftime("%d/%m/%Y %H:%M:%S"),
                        "Contacto": trial.contact, "Demora": trial.bearing_deg.round(3)})
    out["bearings_local.csv"] = log.to_csv(index=False)
    half = local.min() + pd.Timedelta(minutes=10)
    out["campaign/leg1.csv"] = log[(local < half).to_numpy()].to_csv(index=False)
    out["campaign/leg2.csv"] = log[(local >= half).to_numpy()].to_csv(index=False)
    return out


if __name__ == "__main__":
    for name, text in files().items():
        (HERE / name).parent.mkdir(exist_ok=True)
        (HERE / name).write_text(text)
        print(f"wrote {name} ({len(text.encode()):,} bytes)")
