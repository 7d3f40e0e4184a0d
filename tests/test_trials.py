"""A sea-trial kit (issue 38): logs and AIS as real exports write them, own-ship from its AIS,
a campaign in one command. The trial is ``tests/families/bearings2d/ais_trial.py``'s (the
Solent recording, two contacts, 0.5 deg noise); each test changes what a real export would
change and checks what tma reads against what was written."""

import numpy as np
import pandas as pd
import pytest

from tests.conftest import data_paths, run_stage_here
from tests.families.bearings2d import ais_trial
from tma.ais.reports import read_reports

QUIET = ["progress=false", "parallel=serial"]


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    return ais_trial.write_trial(tmp_path_factory.mktemp("trial"))


def _sparse(reports: pd.DataFrame, every_s: float) -> pd.DataFrame:
    """Each ship's reports thinned to one per ``every_s`` (a satellite AIS's)."""
    slot = np.floor((reports.t_s - reports.t_s.min()) / every_s)
    return reports[~pd.DataFrame({"m": reports.mmsi, "s": slot}).duplicated()]


# -- item 7: the small fixes -------------------------------------------------------------------

def test_sparse_ais_is_refused_naming_truth_max_gap_s_and_a_value_that_works(trial, tmp_path,
                                                                             monkeypatch):
    """Ships reported every 5 minutes: every contact is matched, none has a truth under the
    90 s bound; the one line names truth.max_gap_s and a value, which then works (from the
    command line, and dotted in Python as the reader's options are)."""
    import tma

    ais_trial.write_ais_csv(tmp_path / "sparse.csv", _sparse(ais_trial.ais_reports(), 300.0))
    with pytest.raises(ValueError, match=r"truth\.max_gap_s=(\d+) to take") as caught:
        tma.read_log(trial / "trial.csv", truth=tmp_path / "sparse.csv")
    value = int(caught.value.args[0].split("truth.max_gap_s=")[1].split()[0])
    assert 300 <= value <= 620, caught.value
    rec = tma.read_log(trial / "trial.csv", truth=tmp_path / "sparse.csv",
                       options={"truth.max_gap_s": value})
    assert list(rec.truth["label"]) == ["T1", "T2"]
    rec = tma.read_log(trial / "trial.csv", options={"truth.file": str(tmp_path / "sparse.csv"),
                                                     "truth.max_gap_s": value})
    assert list(rec.truth["label"]) == ["T1", "T2"]
    monkeypatch.chdir(trial)
    proc = run_stage_here("ingest", "input=trial.csv", f"truth={tmp_path / 'sparse.csv'}",
                          *data_paths(tmp_path), *QUIET, check=False)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert f"set truth.max_gap_s={value}" in lines[0]


def test_nmea_sentences_that_are_not_ais_are_counted_as_such(tmp_path):
    """A satellite receiver's ``$PGHP`` lines and own-ship's ``$GPRMC`` between the
    ``!AIVDM`` sentences are NMEA of another kind, noted as such; only the garbage line is
    'not a readable AIS sentence'."""
    reports = ais_trial.ais_reports().head(20)
    lines = ais_trial.nmea_lines(reports)
    other = ["$PGHP,1,2016,1,12,13,28,0,0,219,1,,1,,*2A",
             "$GPRMC,132800,A,5047.500,N,00106.300,W,5.0,90.0,120116,,*1D"]
    (tmp_path / "sat.nmea").write_text("\n".join(lines[:10] + other * 3 + lines[10:]
                                                 + ["garbage"]) + "\n")
    got = read_reports(tmp_path / "sat.nmea")
    assert len(got) == 20
    assert got.dropped.reasons["not a readable AIS sentence"]["count"] == 1
    assert any("6 NMEA sentence(s) that are not AIS" in n and "3 $PGHP" in n
               and "3 $GPRMC" in n for n in got.notes), got.notes


# -- item 6: ids as written, from frames too ---------------------------------------------------

def test_a_frame_whose_ids_are_floats_says_that_two_ids_may_be_one(trial):
    """Contacts 7 and 7.0 mixed in a frame: pandas makes the column float64, where they are
    one number; the refusal says so and how to keep them apart, and the ids as text are two
    contacts, as in a CSV."""
    import tma

    frame = pd.read_csv(trial / "trial.csv")
    ids = np.where(frame.contact == "T1", 7, 7.0).astype(object)
    ids[frame.contact.to_numpy() == "T1"] = 7  # the Python int 7 and the float 7.0
    mixed = frame.assign(contact=pd.Series(list(ids)).astype(float))
    with pytest.raises(ValueError, match=r"holds floats .*7 and 7\.0 are one number.*as text"):
        tma.Recording.from_frames(mixed)
    apart = frame.assign(contact=pd.Series(list(ids), dtype=object))
    rec = tma.Recording.from_frames(apart)
    assert sorted(rec.bearings["label"].unique()) == ["7", "7.0"]
    assert any("alike but written differently" in n for n in rec.notes), rec.notes


def test_truth_options_dotted_in_python_are_those_of_the_command_line(trial):
    import tma

    with pytest.raises(ValueError, match="unknown option truth.nothing"):
        tma.read_log(trial / "trial.csv", truth=trial / "trial_ais.csv",
                     options={"truth.nothing": 1})
    rec = tma.read_log(trial / "trial.csv", truth=trial / "trial_ais.csv",
                       options={"truth.match": {"T1": 235031618}})
    assert list(rec.matches["how"]) == ["given", "bearings"]
