"""What one command covers: its scenario points and estimators (``grid``: the grid language),
the datasets they name and the estimator config each runs with (``datasets``), and each stage
as one call from the command line's config (``command``). No Hydra here: ``pipeline/``
composes the config and hands it over as plain values, so every rule is tested without
starting it (``tests/test_experiment.py``).
"""
