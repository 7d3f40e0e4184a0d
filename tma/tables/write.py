"""Tables and plots written by the aggregate stage, one module per family."""

import logging
import os
import sys
from pathlib import Path

import pandas as pd

from tma.io.atomic import atomic_path, write_text_atomic
from tma.tables.markdown import markdown_table

log = logging.getLogger(__name__)


def plots_to_files() -> None:
    """Let matplotlib load whatever ``MPLBACKEND`` says: tma draws every plot into a file
    (the families' aggregate modules use Agg), so a backend matplotlib refuses when it is
    imported (a typo, ``bogus``) must not stop a table. Such a value is left out of the
    environment, with a warning; a valid one stays. Called before a family's aggregate module
    is imported (``tma.families.Family.aggregate``); nothing once matplotlib is loaded."""
    value = os.environ.get("MPLBACKEND")
    if not value or "matplotlib" in sys.modules:
        return
    del os.environ["MPLBACKEND"]
    import matplotlib
    from matplotlib import rcsetup

    try:
        rcsetup.validate_backend(value)
    except ValueError:
        log.warning("MPLBACKEND=%s is no matplotlib backend: left out (tma draws its plots "
                    "into files, with Agg)", value)
        return
    os.environ["MPLBACKEND"] = value
    matplotlib.rcParams["backend"] = value


def write_csv(df: pd.DataFrame, path: Path, float_format=None):
    """CSV without index; floats in shortest round-trip form unless ``float_format``."""
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False, float_format=float_format, lineterminator="\n")


def write_table(tables_dir, name: str, title: str, intro: str, data: pd.DataFrame,
                shown: pd.DataFrame, *, float_format=None, notes: str = "",
                paper=None) -> list[Path]:
    """One table, as every family writes it: ``<name>.csv`` (``data``, every number;
    ``float_format`` as ``write_csv``), ``<name>.md`` (``# title``, ``intro``, the formatted
    cells of ``shown``, ``notes``) and, given ``paper`` = ``(rows, intro)`` (the family's
    comparison, ``tma.tables.paper``), the section "Against the paper" at the end of the Markdown
    and ``<name>_paper.csv``. Returns the paths written: csv, md (, paper csv)."""
    tables_dir = Path(tables_dir)
    paths = [tables_dir / f"{name}.csv", tables_dir / f"{name}.md"]
    write_csv(data, paths[0], float_format=float_format)
    text = f"# {title}\n\n{intro.strip()}\n\n{markdown_table(shown)}"
    if notes:
        text += f"\n{notes.strip()}\n"
    if paper is not None:
        from tma.tables.paper import csv_frame, section

        rows, paper_intro = paper
        text = text.rstrip("\n") + "\n\n" + section(rows, paper_intro)
        paths.append(tables_dir / f"{name}_paper.csv")
        write_csv(csv_frame(rows), paths[-1])
    write_text_atomic(paths[1], text)
    return paths


def table_subplots(*args, **kwargs):
    """``plt.subplots`` for a table's plot, its axes titles at the top of their axes (no plot
    here has ticks there) instead of placed by measuring every tick label on each draw,
    matplotlib's default (a third of the drawing time of a small plot)."""
    import matplotlib.pyplot as plt

    with plt.rc_context({"axes.titley": 1.0}):
        return plt.subplots(*args, **kwargs)


def fixed_layout(fig, *, left=0.8, right=0.25, bottom=0.6, top=0.45, wspace=0.75,
                 hspace=0.85, title=True):
    """Margins and gaps of ``fig``'s grid of axes, in inches (the width of tick labels and an
    axis label, a title): the layout ``tight_layout`` would find for the tables' plots, whose
    labels are short and known, without its measuring pass over every text (a third of the
    time of a small table's plot). ``title``: room for a ``suptitle`` above the axes."""
    width, height = fig.get_size_inches()
    top += 0.35 if title else 0.0
    grid = fig.axes[0].get_subplotspec().get_gridspec()
    rows, cols = grid.get_geometry()
    cell_w = (width - left - right - (cols - 1) * wspace) / cols
    cell_h = (height - top - bottom - (rows - 1) * hspace) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=wspace / cell_w, hspace=hspace / cell_h)


def save_figure(fig, path: Path):
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120, metadata={"Software": None})
