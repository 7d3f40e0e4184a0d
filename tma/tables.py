"""Tables and plots written by the aggregate stage, one module per family."""

from pathlib import Path

import pandas as pd

from tma.io.atomic import atomic_path, write_text_atomic


def write_csv(df: pd.DataFrame, path: Path, float_format=None):
    """CSV without index; floats in shortest round-trip form unless ``float_format``."""
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False, float_format=float_format, lineterminator="\n")


def markdown_table(df: pd.DataFrame) -> str:
    """A GitHub-flavoured Markdown table of already formatted (string) cells."""
    head = "| " + " | ".join(df.columns) + " |"
    rule = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(str(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join([head, rule, *body]) + "\n"


def write_markdown(path: Path, title: str, intro: str, table: str, notes: str = ""):
    text = f"# {title}\n\n{intro.strip()}\n\n{table}"
    if notes:
        text += f"\n{notes.strip()}\n"
    write_text_atomic(path, text)


def save_figure(fig, path: Path):
    from matplotlib.layout_engine import PlaceHolderLayoutEngine

    # ``fig.tight_layout()`` leaves a placeholder layout engine, which does nothing but makes
    # savefig draw the whole figure once more before it draws the file: drop it
    if isinstance(fig.get_layout_engine(), PlaceHolderLayoutEngine):
        fig.set_layout_engine(None)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120, metadata={"Software": None})
