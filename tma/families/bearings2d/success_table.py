"""``bearings2d``'s table of simulated runs: per estimator and bearing noise sigma the
success rates in the four regions of the paper, the fit, the work and the statuses
(``<name>.md``, ``.csv``, ``.png``; ``tma.tables.write.write_table`` adds its section against the
paper)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from tma.families.bearings2d.benchmark import _num  # noqa: E402
from tma.families.bearings2d.metrics import REGIONS, TABLE_COLUMNS  # noqa: E402
from tma.families.bearings2d.status import STATUSES  # noqa: E402
from tma.tables.write import fixed_layout, save_figure, table_subplots, write_table  # noqa: E402

INTRO = """Bearings-only TMA of a constant-velocity target from a manoeuvring observer
(`docs/families.md`). Each row: one estimator at one bearing noise sigma over
N simulated targets. Ref1..Ref4: share of targets whose estimate lies inside the success
region (bearing and distance at the end of the observation, course, speed; Ref1 is the
strictest), with the 95 % Wilson interval. sqrt(Ka) = sqrt(F(theta_hat)/n) in degrees: a
good maximum-likelihood fit gives sqrt(Ka) close to sigma. Nf: evaluations of F, Iter:
accepted LM steps (medians; direct estimators have none). Status: tracks per verdict
({statuses}, see the README).
Consistent: share of the ok tracks whose normalised error (theta_hat - theta)^T Sigma^-1
(theta_hat - theta), Sigma = (J^T J)^-1 sigma^2, lies below the chi-square(4) 95 % point;
about 95 % for honest one-sigma errors. Every number is read from the run files under
`data/runs/`."""


REGION_NOTE = "\n".join(
    f"- {r.capitalize()}: bearing <= {b} deg, distance <= {d:.0%}, course <= {c} deg, "
    f"speed <= {s:.0%}" for r, (b, d, c, s) in REGIONS.items()
)


def _pct(rate, lo, hi):
    return f"{100 * rate:.1f} % ({100 * lo:.1f}-{100 * hi:.1f})"


# the statuses' names in the table's status column
STATUS_ABBREVIATIONS = {"ok": "ok", "not_converged": "not_conv", "poor_fit": "poor_fit",
                        "unobservable": "unobs", "manoeuvring": "manoeuv",
                        "approximate": "approx", "position_only": "pos_only"}
# counted (a column of the CSV, a count in the status column) only where some row has one: a
# status only targets that may manoeuvre get, which a constant-velocity table never shows
COUNTED_WHERE_SEEN = ("position_only",)


def write_success_table(rows: list[dict], tables_dir, name="bearings2d",
                        paper_section=None) -> list[Path]:
    """Write ``<name>.csv``, ``<name>.md`` (with ``paper_section``, ``tables.write_table``)
    and ``<name>.png``; returns their paths. A status of ``COUNTED_WHERE_SEEN`` is counted
    only where some row has one."""
    tables_dir = Path(tables_dir)
    table = pd.DataFrame(rows, columns=TABLE_COLUMNS).sort_values(
        ["estimator", "sigma_deg"], kind="stable").reset_index(drop=True)
    statuses = [s for s in STATUSES
                if s not in COUNTED_WHERE_SEEN or table[f"n_{s}"].fillna(0).any()]
    table = table.drop(columns=[f"n_{s}" for s in STATUSES if s not in statuses])

    shown = pd.DataFrame({
        "estimator": table["estimator"],
        "sigma (deg)": table["sigma_deg"].map("{:g}".format),
        "N": table["n_tracks"],
        **{r.capitalize(): [_pct(*v) for v in table[[r, f"{r}_lo", f"{r}_hi"]].to_numpy()]
           for r in REGIONS},
        "sqrt(Ka) mean (deg)": table["sqrt_ka_mean"].map(_num),
        "sqrt(Ka) median (deg)": table["sqrt_ka_median"].map(_num),
        "Nf median": table["nf_median"].map(lambda x: _num(x, "{:g}")),
        "Iter median": table["iter_median"].map(lambda x: _num(x, "{:g}")),
        "status " + " / ".join(STATUS_ABBREVIATIONS[s] for s in statuses): [
            " / ".join(str(v) for v in r) for r in table[[f"n_{s}" for s in statuses]].to_numpy()],
        "consistent (ok)": [_pct(*v) if pd.notna(v[0]) else "-" for v in
                            table[["consistent", "consistent_lo", "consistent_hi"]].to_numpy()],
    })
    paths = write_table(tables_dir, name, "Bearings-only TMA: success rates by estimator and "
                        "noise", INTRO.format(statuses=" / ".join(statuses)), table, shown,
                        float_format="%.6g",
                        notes="Success regions:\n" + REGION_NOTE, paper=paper_section)
    paths.append(tables_dir / f"{name}.png")

    fig, axes = table_subplots(2, 2, figsize=(10, 7), sharex=True, sharey=True)
    for ax, region in zip(axes.flat, REGIONS, strict=True):
        for estimator, rows_e in table.groupby("estimator", sort=True):
            x = rows_e["sigma_deg"].to_numpy()
            ax.plot(x, 100 * rows_e[region], marker="o", label=estimator)
            ax.fill_between(x, 100 * rows_e[f"{region}_lo"], 100 * rows_e[f"{region}_hi"],
                            alpha=0.2)
        ax.set_title(region.capitalize())
        ax.grid(True, alpha=0.3)
        ax.set_ylim(-2, 102)
    for ax in axes[1]:
        ax.set_xlabel("bearing noise sigma (deg)")
    for ax in axes[:, 0]:
        ax.set_ylabel("success rate (%)")
    axes[0, 0].legend()
    fig.suptitle("Bearings-only TMA: success rate vs noise (95 % Wilson bands)")
    fixed_layout(fig)
    save_figure(fig, paths[-1])
    plt.close(fig)
    return paths
