"""Maths every family may use: ``angles`` (bearings and courses, wrapping), ``linalg`` (scaled
inverses), ``stats`` (intervals and tests), ``geo`` (WGS84 and the local plane, Foxglove fixes)
and ``path`` (a platform's path of legs and turns, integrated exactly).
"""
