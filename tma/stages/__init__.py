"""The stage engines, one module each: ``simulate`` (scenario configs -> datasets), ``ingest``
(a recorded log -> a dataset), ``estimate`` (datasets and estimator configs -> runs) and
``aggregate`` (runs -> metrics and tables). Stages meet only through the files each writes;
``pipeline/`` runs each as a Hydra app, ``tma.plan.command`` as one call from its config.
"""
