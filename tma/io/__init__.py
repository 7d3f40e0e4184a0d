"""File formats shared by the pipeline stages: datasets, logs, manifests, run outputs."""
