"""A campaign of trials scored against AIS from Python (``tma.campaign``): what ``python -m
pipeline.table input=DIR`` tabulates, as one DataFrame (``tma.ais.campaign``)."""

import os

import pandas as pd

from tma.api.options import _nested, _plain


def campaign(input, truth=None, *, estimator: str | None = None,
             sigma_deg: float | None = None, contacts: bool = False,
             options: dict | None = None, **groups) -> pd.DataFrame:
    """Score every log of a folder or a glob (``input``) against its AIS and pool them:
    ``truth`` one AIS file for all, a folder of each log's (``<stem>_ais.csv``...; None: beside
    each log), or the ``truth.*`` options with ``file``; reading and ``truth.*`` options as
    ``read_log``'s (``options={"truth.own_mmsi": 235086588}``), ``estimator`` and
    ``sigma_deg`` as ``estimate``'s. Returns the campaign table: one row per log and one
    ``pooled`` (contacts, with a truth, ``ok``, covered share with its 95 % Wilson interval,
    the ``ok`` contacts' z-scores' mean and sd, gross errors; a log that could not be scored
    has its reason in ``note``); ``contacts=True``: every log's per-contact rows instead
    (``log`` first), as ``estimate`` gives them."""
    from tma.ais.campaign import (
        campaign_logs,
        campaign_table,
        pooled_contacts,
        run_campaign,
        with_refused,
    )
    from tma.api.estimate import estimate
    from tma.api.recording import _with_dotted_truth, read_log

    if not isinstance(input, str | os.PathLike):
        raise TypeError(f"campaign takes a folder or a glob of log files, got "
                        f"{type(input).__name__}; a DataFrame is scored by "
                        "tma.estimate(frame, truth=...)")
    _plain({"truth": truth, "estimator": estimator, "sigma_deg": sigma_deg}, "campaign")
    reading = _nested(options, groups)
    node = _with_dotted_truth(truth, reading.pop("truth", None))
    node = {} if node is None else dict(node) if isinstance(node, dict) else {"file": node}
    pairs = campaign_logs(input, node.get("file"))

    def score(log, ais, _stem):
        rec = read_log(log, truth={**node, "file": str(ais)}, sigma_deg=sigma_deg,
                       options=reading)
        return estimate(rec, estimator)

    reports, refused = run_campaign(pairs, score, f"input={input}")
    if contacts:
        return pooled_contacts(reports)
    return with_refused(campaign_table(reports), refused)
