"""A campaign of sea trials scored against AIS in one go: the logs of a folder or a glob, each
with its AIS (or one AIS for all), each scored as ``table input=LOG truth=AIS`` scores one,
and one table that pools their verdicts (``python -m pipeline.table input=DIR``,
``tma.campaign``).

Which AIS each log has (``campaign_logs``): ``truth=FILE`` is every log's; ``truth=DIR`` (or
no ``truth=``: the logs' own folder) holds each log's as ``<stem>_ais.<ext>`` or
``<stem>.<ext>`` of another extension than the log's (``trial3.csv`` and ``trial3_ais.nmea``).
Files named ``*_ais.*`` are AIS, never logs. A log without its AIS, or a folder without a
log, is refused in one line.

The campaign table (``campaign_table``), one row per log and one ``pooled``, over the
contacts with a truth: how many contacts, with a truth, ``ok``; the ``ok`` share; the covered
share of the ``ok`` ones (their truth within the estimate's 95 % region) with its 95 % Wilson
interval (honest errors cover 95 %); per quantity (range, course, speed) the mean and the
standard deviation of the ``ok`` contacts' z-scores (honest errors: 0 and 1), how many lie
beyond 3, and the share whose truth lies inside the answer's own 95.4 % interval
(``<q>_in_interval``, with its Wilson interval ``_lo``, ``_hi``: honest answers 95.4 %)
(course and speed: not of a contact whose
truth's velocity is uncertain by about its size, sparse AIS:
``truth_report.vague_velocity``, a z-score against it tests nothing); the
gross errors: ``ok`` contacts whose normalised error (NEES) exceeds the
chi-square(4) 99.9 % point, which honest errors pass once in a thousand. The plot
(``write_campaign``) sets the pooled z-scores' histograms against the standard normal and
each log's covered share with its interval against 95 %.
"""

import glob as globbing
import hashlib
import re
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.special import gammaincinv

from tma.ais.options import TruthError, TruthFileNotFound

NEES_999 = float(2 * gammaincinv(2.0, 0.999))  # chi-square(4) 99.9 % point: a gross error

QUANTITIES = ("range", "course", "speed")
Z_GROSS = 3.0
COUNTS = ("contacts", "with_truth", "ok", "covered", "gross_errors")
LOG_EXTENSIONS = (".csv", ".tsv", ".txt", ".mcap")
AIS_EXTENSIONS = (".csv", ".csv.gz", ".nmea", ".txt", ".log", ".parquet", ".gz")


def is_campaign(input_path) -> bool:
    """``input=`` names several logs: a folder, or a glob (``logs/*.csv``)."""
    text = str(input_path)
    return Path(text).is_dir() or any(c in text for c in "*?[")


def _is_ais_name(path: Path) -> bool:
    return path.name.split(".")[0].endswith("_ais")


def campaign_logs(input_path, truth) -> list[tuple[Path, Path]]:
    """``(log, its AIS)`` of every log ``input_path`` (a folder or a glob) names, sorted;
    ``truth``: one AIS file for all, a folder of each log's, or None (beside each log)."""
    text = str(input_path)
    if Path(text).is_dir():
        found = [p for p in sorted(Path(text).iterdir())
                 if p.is_file() and p.suffix.lower() in LOG_EXTENSIONS]
    else:
        found = [Path(p) for p in sorted(globbing.glob(text)) if Path(p).is_file()]
    single = None if truth is None or Path(str(truth)).is_dir() else Path(str(truth))
    logs = [p for p in found if not _is_ais_name(p) and (single is None or
                                                          p.resolve() != single.resolve())]
    if not logs:
        raise TruthFileNotFound(f"input={text}: no log there (files with "
                                f"{', '.join(LOG_EXTENSIONS)}, not named *_ais.*)")
    if single is not None:
        if not single.is_file():
            raise TruthFileNotFound(f"truth={single}: no such file")
        return [(log, single) for log in logs]
    folder = None if truth is None else Path(str(truth))
    pairs = []
    for log in logs:
        where = folder or log.parent
        stem = log.name.split(".")[0]
        candidates = [p for p in sorted(where.glob(f"{stem}*")) if p.is_file() and p != log
                      and p.name.split(".")[0] in (stem, f"{stem}_ais")
                      and "".join(p.suffixes).lower() in AIS_EXTENSIONS]
        if not candidates:
            raise TruthFileNotFound(
                f"input={text}: log {log.name} has no AIS: name it {stem}_ais.csv (or .nmea, "
                f".parquet) in {where}, or give one AIS for all with truth=FILE")
        if len(candidates) > 1:
            raise TruthError(f"input={text}: log {log.name} has {len(candidates)} AIS files "
                             f"({', '.join(p.name for p in candidates)}): keep one, or give "
                             "truth=FILE")
        pairs.append((log, candidates[0]))
    return pairs


def _share(k, n):
    return k / n if n else np.nan


def _row(name: str, report: pd.DataFrame) -> dict:
    """One row of the campaign table from a log's report (``tma.estimate``'s columns)."""
    from tma.maths.stats import wilson_interval

    has = report["covered"].notna() if "covered" in report else pd.Series(False,
                                                                          index=report.index)
    ok = (report["status"] == "ok") & has
    k, n = int(report.loc[ok, "covered"].astype(bool).sum()), int(ok.sum())
    lo, hi = wilson_interval(k, n)
    row = {"log": name, "contacts": len(report), "with_truth": int(has.sum()),
           "ok": n, "ok_share": _share(n, int(has.sum())), "covered": k,
           "covered_share": _share(k, n), "covered_lo": float(lo), "covered_hi": float(hi)}
    from tma.families.bearings2d.calibration import within_shares
    from tma.families.bearings2d.truth_report import vague_velocity

    vague = vague_velocity(report)  # sparse AIS: a course/speed z against it tests nothing
    for q in QUANTITIES:
        use = ok & ~vague if q in ("course", "speed") else ok
        z = report.loc[use, f"{q}_z"].to_numpy(float) if f"{q}_z" in report else np.array([])
        z = z[np.isfinite(z)]
        row[f"{q}_z_mean"] = float(z.mean()) if z.size else np.nan
        row[f"{q}_z_sd"] = float(z.std(ddof=1)) if z.size > 1 else np.nan
        row[f"{q}_z_beyond_3"] = int((np.abs(z) > Z_GROSS).sum())
        # the truth inside the answer's own 95.4 % interval (truth_report's interval z), with
        # its Wilson interval
        iz = report.loc[use, f"{q}_iz"] if f"{q}_iz" in report else np.array([])
        shares = within_shares(iz, q)
        row.update({f"{q}_in_interval{end}": shares[f"{q}_within_2sd{end}"]
                    for end in ("", "_lo", "_hi")})
    nees = report.loc[ok, "nees"].to_numpy(float) if "nees" in report else np.array([])
    row["gross_errors"] = int((nees > NEES_999).sum())
    return row


def campaign_table(reports: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """One row per log of ``reports`` (``{log name: its per-contact report}``) and the
    ``pooled`` row (module docstring)."""
    rows = [_row(name, report) for name, report in reports.items()]
    pooled = pd.concat([r.assign(log=name) for name, r in reports.items()], ignore_index=True)
    rows.append(_row("pooled", pooled))
    return pd.DataFrame(rows)


def pooled_contacts(reports: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Every log's contacts in one frame, ``log`` first."""
    return pd.concat([r.assign(log=name)[["log", *r.columns]] for name, r in reports.items()],
                     ignore_index=True)


def campaign_text(table: pd.DataFrame) -> str:
    """The pooled verdict in one line, for the log and under the table."""
    p = table.iloc[-1]
    refused = int((table.get("note", pd.Series(dtype=str)).fillna("") != "").sum())
    logs = len(table) - 1  # every log, scored or not
    ok, covered = int(p["ok"]), int(p["covered"])
    head = (f"Campaign of {logs} log(s) ({refused} not scored): {int(p['with_truth'])} of "
            f"{int(p['contacts'])} contacts have a truth")
    if not ok:
        return f"{head}, none of them `ok`."
    return (f"{head}, {ok} `ok` ({100 * p['ok_share']:.0f} %); {covered} of "
            f"them covered ({100 * p['covered_share']:.0f} %, 95 % interval "
            f"{100 * p['covered_lo']:.0f}-{100 * p['covered_hi']:.0f} %; honest errors cover "
            f"95 %); {int(p['gross_errors'])} gross error(s).")


def _markdown(table: pd.DataFrame) -> str:
    def pct(v):
        return "-" if not np.isfinite(v) else f"{100 * v:.0f} %"

    def z(row, q):
        m, s = row[f"{q}_z_mean"], row[f"{q}_z_sd"]
        return "-" if not np.isfinite(m) else (
            f"{m:+.2f} / {s:.2f}" if np.isfinite(s) else f"{m:+.2f} / -")

    head = ["log", "contacts", "with truth", "ok", "covered (95 % interval)",
            *[f"z {q} mean / sd" for q in QUANTITIES], "beyond 3 sd (r / c / s)",
            "in [a, b] (r / c / s)", "gross errors"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, row in table.iterrows():
        if isinstance(row.get("note"), str) and row["note"]:
            lines.append(f"| `{row['log']}` | not scored: {row['note']} |"
                         + " |" * (len(head) - 2))
            continue
        covered = ("-" if not row["ok"] else
                   f"{row['covered']} of {row['ok']}: {pct(row['covered_share'])} "
                   f"({pct(row['covered_lo'])}-{pct(row['covered_hi'])})")
        name = f"**{row['log']}**" if row["log"] == "pooled" else f"`{row['log']}`"
        beyond = " / ".join(str(row[f"{q}_z_beyond_3"]) for q in QUANTITIES)
        inside = " / ".join(pct(row.get(f"{q}_in_interval", np.nan)) for q in QUANTITIES)
        lines.append("| " + " | ".join([
            name, str(row["contacts"]), str(row["with_truth"]),
            f"{row['ok']} ({pct(row['ok_share'])})", covered,
            *[z(row, q) for q in QUANTITIES], beyond, inside, str(row["gross_errors"])]) + " |")
    return "\n".join(lines)


def write_campaign(table: pd.DataFrame, contacts: pd.DataFrame, tables_dir, name: str
                   ) -> list[Path]:
    """``<name>.md``, ``<name>.csv`` (the table) and ``<name>.png`` (the plot) in
    ``tables_dir``."""
    from tma.io.atomic import write_text_atomic

    out = Path(tables_dir)
    out.mkdir(parents=True, exist_ok=True)
    intro = (f"# Campaign against AIS: {name}\n\nEach log scored against the AIS of its trial "
             "(its own table beside this one), then pooled. ok: contacts with a truth whose "
             "answer is `ok`; covered: the truth within the estimate's 95 % region of position "
             "and velocity (honest errors cover 95 %; the interval is Wilson's); z: (estimate "
             "- truth) / one sigma of the `ok` contacts (honest errors: mean 0, sd 1; |z| > 3 "
             "counted per range / course / speed; course and speed not of a contact whose "
             "truth's velocity is uncertain by about its size); in [a, b]: the share of the "
             "`ok` contacts whose truth lies inside the answer's own 95.4 % interval (the "
             "tables' [a, b]; honest answers: 95.4 %); gross errors: `ok` contacts whose "
             "normalised error exceeds the chi-square(4) 99.9 % point. "
             f"`{name}.png`: the pooled z-scores against the standard normal, and each log's "
             "covered share.\n\n")
    md, csv = out / f"{name}.md", out / f"{name}.csv"
    write_text_atomic(md, intro + _markdown(table) + "\n\n" + campaign_text(table) + "\n")
    write_text_atomic(csv, table.to_csv(index=False, float_format="%.6g"))
    return [md, csv, _plot(table, contacts, out / f"{name}.png")]


def _plot(table: pd.DataFrame, contacts: pd.DataFrame, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tma.io.atomic import atomic_path

    fig, axes = plt.subplots(1, 4, figsize=(15, 3.6))
    ok = (contacts["status"] == "ok") & contacts.get("covered", pd.Series(dtype=object)).notna()
    grid = np.linspace(-4, 4, 161)
    for ax, q in zip(axes[:3], QUANTITIES, strict=True):
        z = contacts.loc[ok, f"{q}_z"].to_numpy(float) if f"{q}_z" in contacts else []
        z = np.clip(np.asarray(z)[np.isfinite(z)], -4, 4)
        ax.hist(z, bins=np.linspace(-4, 4, 17), density=True, color="tab:blue", alpha=0.6,
                label=f"ok contacts ({z.size})")
        ax.plot(grid, np.exp(-grid ** 2 / 2) / np.sqrt(2 * np.pi), color="k",
                label="standard normal")
        ax.set_title(f"{q} z-score")
        ax.legend(fontsize=7)
    ax = axes[3]
    table = table[table["contacts"].notna()]
    logs = table.iloc[:-1]
    x = np.arange(len(table))
    share = table["covered_share"].to_numpy(float)
    err = np.abs(np.vstack([share - table["covered_lo"], table["covered_hi"] - share]))
    ax.errorbar(x, share, yerr=np.nan_to_num(err), fmt="o", color="tab:blue")
    ax.axhline(0.95, color="k", ls="--", lw=1, label="95 %")
    ax.set_xticks(x, [*logs["log"].astype(str), "pooled"], rotation=45, ha="right",
                  fontsize=7)
    ax.set_ylim(0, 1.05)
    ax.set_title("covered share of ok contacts")
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
    return path


def campaign_name(input_path, name=None) -> str:
    """The campaign's name: ``name=``, else the folder's (or the glob's folder's) name."""
    if name:
        return str(name)
    path = Path(str(input_path))
    folder = path if path.is_dir() else Path(globbing.escape(str(path))).parent
    while any(c in str(folder.name) for c in "*?["):
        folder = folder.parent
    return folder.resolve().name or "campaign"


def _plain_name(text: str) -> str:
    """``text`` as a plain file name: ``/`` as ``-``, anything but letters, digits, ``._-``
    as ``_``."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", text.replace("/", "-")).strip("-") or "log"


def log_labels(logs) -> dict[Path, tuple[str, str]]:
    """Each log's ``(row label, dataset stem)``, unique within ``logs`` and the same on every
    run over the same logs: its file name (and its stem) where that alone tells it apart,
    else the shortest trailing part of its path that does (``d1/leg.csv``, ``d1-leg``), so
    that logs of one name in several folders (``input='days/*/leg.csv'``) are each scored
    under their own name, none overwriting another."""
    paths = [Path(p) for p in logs]
    parts = {p: p.resolve().parts for p in paths}
    longest = max((len(v) for v in parts.values()), default=1)
    for depth in range(1, longest + 1):
        labels = {p: "/".join(parts[p][-depth:]).lstrip("/") for p in paths}
        if len(set(labels.values())) < len(paths):
            continue
        stems = {p: _plain_name("/".join([*parts[p][-depth:-1], p.name.split(".")[0]]))
                 for p in paths}
        # names alike once made plain (``d 1``, ``d_1``; ``leg.csv``, ``leg.tsv``): each
        # with a short hash of its own label, stable from run to run
        return {p: (labels[p], stems[p] if list(stems.values()).count(stems[p]) == 1 else
                    f"{stems[p]}-{hashlib.sha1(labels[p].encode()).hexdigest()[:6]}")
                for p in paths}
    raise TruthError(f"the same log twice among {', '.join(map(str, paths))}: name each once")


def log_name(campaign: str, stem: str, named: bool) -> str:
    """A log's dataset name from its stem (``log_labels``), after the campaign's name when
    ``name=`` gave one."""
    return f"{campaign}-{stem}" if named else stem


def run_campaign(pairs, score, where: str) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """Each ``(log, ais)`` of ``pairs`` scored by ``score(log, ais, stem) -> report`` (its
    per-contact report; ``stem`` its dataset's plain name, ``log_labels``):
    ``({label: report}, {label: the one line that refused it})``, each log under its own label
    (``log_labels``). A log that cannot be scored is said and the campaign goes on; none
    scored is one line."""
    import logging

    from tma.errors import TmaError

    log = logging.getLogger(__name__)
    reports, refused = {}, {}
    labels = log_labels([path for path, _ in pairs])
    for path, ais in pairs:
        label, stem = labels[path]
        try:
            reports[label] = score(path, ais, stem)
        except (TmaError, FileNotFoundError) as exc:
            refused[label] = " ".join(str(exc).split())
            log.warning("%s: log %s not scored: %s", where, label, refused[label])
    if not reports:
        first = next(iter(refused.items()))
        raise TruthError(f"{where}: no log of the campaign could be scored ({len(refused)} "
                         f"refused; {first[0]}: {first[1]})")
    return reports, refused


def with_refused(table: pd.DataFrame, refused: dict[str, str]) -> pd.DataFrame:
    """The campaign table with a row per refused log (its reason in ``note``)."""
    table = table.assign(note="")
    if not refused:
        return table
    rows = pd.DataFrame([{"log": name, "note": why} for name, why in refused.items()])
    logs = pd.concat([table.iloc[:-1], rows]).sort_values("log", kind="stable")
    table = pd.concat([logs, table.iloc[-1:]], ignore_index=True)  # the logs in file order
    counts = [c for c in table.columns if c in COUNTS or c.endswith("_beyond_3")]
    return table.astype({c: "Int64" for c in counts})  # counts stay whole beside the gaps


def write_campaign_tables(reports: dict[str, pd.DataFrame], refused: dict[str, str],
                          tables_dir, name: str) -> list[Path]:
    """The campaign table of ``reports`` (and the ``refused`` logs) written as
    ``write_campaign`` writes it; its verdict logged."""
    import logging

    table = with_refused(campaign_table(reports), refused)
    logging.getLogger(__name__).info("%s", campaign_text(table))
    return write_campaign(table, pooled_contacts(reports), tables_dir, name)
