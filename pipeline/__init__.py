"""Thin Hydra entry points, one verb each: ``python -m pipeline.<verb>``."""
