"""Our tables beside the published studies: the section "Against the paper" of each family's
Markdown table and ``<table>_paper.csv`` (columns ``COLUMNS``).

Each family transcribes what its paper published (``tma/families/<family>/paper.py``, from
``docs/families.md``) and holds its own table against it with these pieces; nothing
here, nor there, feeds back into an estimator.

**Published numbers.** One row each: the paper's value, ours with its 95 % interval, the
difference in standard errors ``z = (ours - paper) / SE`` and a verdict:

- ``reproduced``: |z| <= 2; ``differs``: |z| > 2;
- ``not comparable``: the setting is not in our table, our scenario or estimator settings are
  not the paper's, or the paper does not say which summary it printed (mean, median, ...) and
  the candidates disagree; the note says which.

``SE = sqrt(se_ours^2 + se_paper^2 + u^2 / 12)``: our standard error, the paper's sampling
error where the family knows it (a share of n targets, or the spread of one run), and the
rounding of the printed value, u = one unit of its last printed digit taken as a uniform error
("1.000": u = 0.001; "about 1e6", one significant figure: u = 1e6). For a share of the paper's
n targets the two sampling errors are those of the pooled two-proportion test,
p(1 - p)(1/n_ours + 1/n_paper) with p the pooled share.

**Intervals of ours** (``Measured``): shares, Wilson; means, normal (mean +- 1.96 sd/sqrt(n));
medians and other quantiles, distribution-free order statistics (ranks n q +- 1.96
sqrt(n q (1 - q))), se = interval / 3.92; ratios of means, the delta method.

**Claims.** One row each: the claim, the statistic it is held against (named exactly), the
measured value and ``holds`` / ``does not hold`` / ``not comparable``.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.special import ndtri

from tma.maths.stats import wilson_interval
from tma.tables.markdown import markdown_table

COLUMNS = ["family", "quantity", "setting", "paper", "ours", "ours_lo", "ours_hi", "z",
           "verdict", "note"]
Z_LIMIT = 2.0  # |z| at most this: reproduced
Z95 = float(ndtri(0.975))
REPRODUCED, DIFFERS, NOT_COMPARABLE = "reproduced", "differs", "not comparable"
HOLDS, DOES_NOT_HOLD = "holds", "does not hold"
SECTION = "## Against the paper"


def printed_unit(text: str) -> float:
    """One unit of the last printed digit of a published number: "1.000" -> 0.001, "10" -> 1,
    "1e6" (one significant figure) -> 1e6, "0.7" -> 0.1."""
    mantissa, _, exponent = text.strip().lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


@dataclass(frozen=True)
class Published:
    """One number as the paper printed it (``text``, e.g. "0.942" or "1e6"). ``quantity``,
    ``setting``: how our table names it; ``n``: the paper's sample size when the number is a
    share of n (its sampling error is then known); ``row``: the paper's table row it was
    transcribed from (None for a number derived in the text)."""

    family: str
    quantity: str
    setting: str
    text: str
    n: int | None = None
    row: str | None = None

    @property
    def value(self) -> float:
        return float(self.text)

    @property
    def unit(self) -> float:
        return printed_unit(self.text)


@dataclass(frozen=True)
class Measured:
    """A statistic of ours with its standard error and 95 % interval (``how`` names the
    interval); ``n``, ``k``: sample size and successes of a share (pooled test)."""

    value: float
    se: float
    lo: float
    hi: float
    how: str
    n: int | None = None
    k: int | None = None


def share(k: int, n: int) -> Measured:
    """A share k/n with its Wilson interval (se of the binomial at k/n)."""
    p = k / n
    lo, hi = wilson_interval(k, n)
    lo, hi = (0.0 if k == 0 else float(lo)), (1.0 if k == n else float(hi))  # no round-off
    return Measured(p, float(np.sqrt(p * (1 - p) / n)), lo, hi, "Wilson", n=n, k=k)


def mean(values) -> Measured:
    """The mean of the finite ``values`` with the normal interval."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Measured(np.nan, np.nan, np.nan, np.nan, "normal")
    se = float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else np.nan
    m = float(x.mean())
    return Measured(m, se, m - Z95 * se, m + Z95 * se, "normal")


def quantile(values, q: float) -> Measured:
    """The q-quantile of ``values`` (NaN dropped; +-inf kept as order statistics) with the
    distribution-free order-statistic interval; se = interval width / 3.92."""
    x = np.sort(np.asarray(values, float)[~np.isnan(np.asarray(values, float))])
    n = x.size
    if n == 0:
        return Measured(np.nan, np.nan, np.nan, np.nan, "order statistics")
    half = Z95 * np.sqrt(n * q * (1 - q))  # ranks (1-based) floor(nq - half), ceil(nq + half)
    lo = x[int(np.clip(np.floor(n * q - half) - 1, 0, n - 1))]
    hi = x[int(np.clip(np.ceil(n * q + half) - 1, 0, n - 1))]
    value = float(np.quantile(x, q)) if np.isfinite(x).all() else float(
        x[int(np.clip(round(q * (n - 1)), 0, n - 1))])
    with np.errstate(invalid="ignore"):
        se = float((hi - lo) / (2 * Z95))
    return Measured(value, se, float(lo), float(hi), "order statistics")


def median(values) -> Measured:
    return quantile(values, 0.5)


def ratio(a: Measured, b: Measured) -> Measured:
    """a / b of two independent estimates, delta-method se and normal interval."""
    r = a.value / b.value
    se = abs(r) * float(np.hypot(a.se / a.value, b.se / b.value))
    return Measured(r, se, r - Z95 * se, r + Z95 * se, "delta method")


def power(a: Measured, exponent: float) -> Measured:
    """a ** exponent, delta-method se and normal interval."""
    v = a.value ** exponent
    se = abs(exponent * a.value ** (exponent - 1)) * a.se
    return Measured(v, se, v - Z95 * se, v + Z95 * se, "delta method")


def z_score(paper: Published, ours: Measured, paper_se: float = 0.0) -> float:
    """(ours - paper) / SE as in the module docstring; 0 when both agree exactly with SE 0."""
    diff = ours.value - paper.value
    if paper.n is not None and ours.n is not None:  # two shares: pooled sampling error
        p = (ours.k + paper.value * paper.n) / (ours.n + paper.n)
        sampling = p * (1 - p) * (1 / ours.n + 1 / paper.n)
    else:
        sampling = ours.se ** 2 + paper_se ** 2
    se = np.sqrt(sampling + paper.unit ** 2 / 12)
    if diff == 0:
        return 0.0
    return float(diff / se) if se > 0 else float(np.copysign(np.inf, diff))


def _row(paper: Published, ours: Measured | None, z, verdict: str, note: str) -> dict:
    missing = ours is None
    return {"family": paper.family, "quantity": paper.quantity, "setting": paper.setting,
            "paper": paper.text, "ours": np.nan if missing else ours.value,
            "ours_lo": np.nan if missing else ours.lo, "ours_hi": np.nan if missing else ours.hi,
            "z": z, "verdict": verdict, "note": note, "kind": "number",
            "how": "" if missing else ours.how}


def not_comparable(paper: Published, reason: str, ours: Measured | None = None) -> dict:
    return _row(paper, ours, np.nan, NOT_COMPARABLE, reason)


def compare(paper: Published, ours: Measured | None, paper_se: float = 0.0, note: str = "",
            why: str = "") -> dict:
    """One published number against ours: z and the verdict. ``ours`` None: the setting is
    not in our table. ``why``: the known reason, added to the note when they differ."""
    if ours is None or not np.isfinite(ours.value):
        return not_comparable(paper, note or "the setting is not in this table")
    z = z_score(paper, ours, paper_se)
    verdict = REPRODUCED if abs(z) <= Z_LIMIT else DIFFERS
    note = "; ".join(filter(None, [note, why if verdict == DIFFERS else ""]))
    return _row(paper, ours, z, verdict, note)


def compare_candidates(paper: Published, candidates: dict, paper_se: float = 0.0,
                       why: str = "") -> dict:
    """A number whose statistic the paper does not name: each candidate summary of ours
    (``{"mean": Measured, "median": Measured, ...}``) is compared; one verdict if they agree,
    else ``not comparable``. The row shows the first candidate."""
    rows = {name: compare(paper, m, paper_se) for name, m in candidates.items()}
    verdicts = {r["verdict"] for r in rows.values()}
    detail = ", ".join(f"{name} {r['ours']:.4g} (z {r['z']:+.1f})" for name, r in rows.items()
                       if r["verdict"] != NOT_COMPARABLE)
    first = next(iter(candidates.values()))
    lead = f"the paper does not say which summary it printed ({' or '.join(candidates)}); ours: "
    if len(verdicts) == 1 and NOT_COMPARABLE not in verdicts:
        verdict = verdicts.pop()
        note = "; ".join(filter(None, [lead + detail, why if verdict == DIFFERS else ""]))
        return {**rows[next(iter(rows))], "note": note}
    if verdicts == {NOT_COMPARABLE}:
        return next(iter(rows.values()))
    return not_comparable(paper, lead + detail + ": they disagree", first)


def claim(family: str, quantity: str, setting: str, paper_text: str, statistic: str,
          ours: Measured | float | None, holds: bool | None, note: str = "") -> dict:
    """A qualitative claim held against one statistic of ours. ``holds`` None: not
    comparable (``note`` says why)."""
    if isinstance(ours, Measured):
        value, lo, hi, how = ours.value, ours.lo, ours.hi, ours.how
    else:
        value, lo, hi, how = (np.nan if ours is None else float(ours)), np.nan, np.nan, ""
    verdict = NOT_COMPARABLE if holds is None else HOLDS if holds else DOES_NOT_HOLD
    return {"family": family, "quantity": quantity, "setting": setting, "paper": paper_text,
            "ours": value, "ours_lo": lo, "ours_hi": hi, "z": np.nan, "verdict": verdict,
            "note": note, "kind": "claim", "statistic": statistic, "how": how}


def config_differences(config: dict, defaults: dict, keys=None, ignore=()) -> list[str]:
    """``key = ours (paper: theirs)`` for every setting of ``config`` that is not the paper's
    (``defaults``): only ``keys`` if given, else every key but ``ignore``; nested dicts
    compared by dotted key, a key absent from ``config`` counts as the default."""
    def flat(node, prefix=""):
        out = {}
        for k, v in node.items():
            if isinstance(v, dict) and v:
                out.update(flat(v, f"{prefix}{k}."))
            else:
                out[f"{prefix}{k}"] = v
        return out

    ours, paper = flat(config), flat(defaults)
    names = [k for k in paper if (k in keys if keys is not None else
                                  not any(k == i or k.startswith(f"{i}.") for i in ignore))]
    return [f"{k} = {ours[k]} (paper: {paper[k]})" for k in names
            if k in ours and not _same(ours[k], paper[k])]


def _same(a, b) -> bool:
    if isinstance(a, int | float) and isinstance(b, int | float) and not isinstance(a, bool):
        return bool(np.isclose(a, b, rtol=1e-12, atol=0))
    return a == b


def by_setting(runs, key, mismatch) -> dict:
    """One run per setting (``key(run)``): of several (a sweep), one with the paper's settings
    (``mismatch(run)`` empty) if there is one."""
    return {key(r): r for r in sorted(runs, key=lambda r: not mismatch(r))}


def differs_reason(scenario: list[str], estimator: list[str] = ()) -> str:
    """The note of a row whose settings are not the paper's ("" when they are)."""
    parts = ([f"scenario not the paper's: {', '.join(scenario)}"] if scenario else []) + (
        [f"estimator not the paper's: {', '.join(estimator)}"] if estimator else [])
    return "; ".join(parts)


# -- the outputs -------------------------------------------------------------------------------

def _num(x) -> str:
    if x is None or (isinstance(x, float) and np.isnan(x)):
        return "-"
    if isinstance(x, str):
        return x
    if np.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.4g}"


def _ours(row: dict) -> str:
    text = _num(row["ours"])
    if np.isfinite(row["ours_lo"]) or np.isfinite(row["ours_hi"]):
        text += f" ({_num(row['ours_lo'])} to {_num(row['ours_hi'])}, {row['how']})"
    return text


def counts(rows: list[dict]) -> str:
    """"n reproduced, ..." over the number rows and "... hold" over the claims."""
    numbers = [r["verdict"] for r in rows if r["kind"] == "number"]
    claims = [r["verdict"] for r in rows if r["kind"] == "claim"]
    parts = []
    if numbers:
        parts.append("published numbers: " + ", ".join(
            f"{numbers.count(v)} {v}" for v in (REPRODUCED, DIFFERS, NOT_COMPARABLE)))
    if claims:
        parts.append("claims: " + ", ".join(
            f"{claims.count(v)} {v}" for v in (HOLDS, DOES_NOT_HOLD, NOT_COMPARABLE)))
    return "; ".join(parts)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")  # a pipe would end the Markdown cell


def _z(z: float) -> str:
    return f"{z:+.2f}" if np.isfinite(z) else ("-" if np.isnan(z) else f"{z:+}")


def section(rows: list[dict], intro: str) -> str:
    """The Markdown section: intro, counts, the numbers table and the claims table."""
    numbers = [r for r in rows if r["kind"] == "number"]
    claims = [r for r in rows if r["kind"] == "claim"]
    parts = [SECTION, intro.strip(), f"Verdicts: {counts(rows)}."]
    if numbers:
        parts.append("### Published numbers\n\n" + markdown_table(pd.DataFrame({
            "quantity": [r["quantity"] for r in numbers],
            "setting": [r["setting"] for r in numbers],
            "paper": [r["paper"] for r in numbers],
            "ours (95 % interval)": [_ours(r) for r in numbers],
            "z": [_z(r["z"]) for r in numbers],
            "verdict": [r["verdict"] for r in numbers],
            "note": [r["note"] for r in numbers]}).map(_cell)).rstrip())
    if claims:
        parts.append("### Claims\n\n" + markdown_table(pd.DataFrame({
            "claim": [r["quantity"] for r in claims],
            "setting": [r["setting"] for r in claims],
            "paper": [r["paper"] for r in claims],
            "statistic of ours": [r["statistic"] for r in claims],
            "measured (95 % interval)": [_ours(r) for r in claims],
            "verdict": [r["verdict"] for r in claims],
            "note": [r["note"] for r in claims]}).map(_cell)).rstrip())
    return "\n\n".join(parts) + "\n"


def csv_frame(rows: list[dict]) -> pd.DataFrame:
    """The CSV's rows: a claim's note starts with its statistic."""
    out = []
    for r in rows:
        note = r["note"]
        if r["kind"] == "claim":
            note = "; ".join(filter(None, [f"statistic: {r['statistic']}", note]))
        out.append({**{c: r[c] for c in COLUMNS}, "note": note})
    return pd.DataFrame(out, columns=COLUMNS)
