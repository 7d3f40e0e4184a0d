"""AIS as ground truth, in the core: the ships around a trial, read from their AIS, as the
truth of a recorded log and as the real motion of simulated scenarios.

One small file per job:

- ``options.py``: the ``truth.*`` options of ``ingest`` (``TruthOptions``) and the errors a
  truth file can cause (``TruthError``, a ``ValueError``; ``TruthFileNotFound``);
- ``reports.py``: decoded position reports (CSV as the common exports write them) or raw NMEA
  ``!AIVDM``/``!AIVDO`` sentences (decoded with pyais) -> one table of position reports
  (``Reports``: MMSI, UTC time, latitude, longitude), bad sentences dropped and counted;
- ``tracks.py``: a vessel's reports as a track (``VesselTrack``): duplicates and position
  spikes dropped, positions on a local east-north plane (``tma.geo``), linear interpolation
  and the gaps it bridges, mean velocities;
- ``match.py``: which ship each contact of a bearing log is (a map the user gives, or the
  bearings each ship would have produced), said per contact, never guessed;
- ``truth.py``: the truth of a recorded bearing log from its AIS (``log_truth``): what
  ``ingest truth=FILE`` stores as ``truth.parquet`` and ``truth_track.parquet``;
- ``pairs.py``: motion samples of a vessel over a window and the automatic pair finder of the
  real-motion scenarios (own-ship windows with a turn, targets within reach);
- ``recording.py``: a recording read once per process for the scenarios, and their option
  group ``real`` (``RealPairs``: own-ship and target, ``bearings2d``; ``RealWindows``: a
  vessel before a fixed sensor, ``radar2d``).
"""
