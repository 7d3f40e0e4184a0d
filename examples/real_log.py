# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # A navigation export of real ship motion, from CSV to contacts, plot and map
#
# The log: a navigation export (`timestamp_utc, latitude_deg, longitude_deg, bearing_deg,
# track`) of real ship motion: own-ship a vessel turning in the Solent, its contact another
# vessel, both from a public AIS recording (`tests/data/ais`, Stone Soup's demo data, MIT
# licence), bearings every 5 s from the true geometry with 0.5 deg noise. Run it as a script
# (`python examples/real_log.py [CSV]`, outputs in `$TMA_EXAMPLE_OUT` or a new temporary
# directory) or open it as a notebook (jupytext).

# %%
import os
import sys
import tempfile
from pathlib import Path

import pandas as pd

import tma

REPO = Path(__file__).resolve().parents[1]
out = Path(os.environ.get("TMA_EXAMPLE_OUT") or tempfile.mkdtemp(prefix="tma-"))
out.mkdir(parents=True, exist_ok=True)
given = [a for a in sys.argv[1:] if a.endswith((".csv", ".tsv"))]  # (a notebook has others)
if given:
    csv = Path(given[0])
else:  # a bundled AIS case: a steady contact 4 km off a turning own-ship
    sys.path.insert(0, str(REPO / "tests" / "data" / "ais"))
    import build_cases

    exports, truth = build_cases.build_cases()
    csv = out / "solent.csv"
    exports["case_11"].loc[:, list(build_cases.EXPORT_COLUMNS)].to_csv(csv, index=False)
print(f"log {csv}, outputs in {out}")

# %% [markdown]
# Read it as `python -m pipeline.ingest input=<csv> sigma_deg=0.5` would: every choice it
# makes by itself is noted.

# %%
recording = tma.read_log(csv, sigma_deg=0.5)
print(recording)
print("\n".join(recording.notes))
recording.bearings.head()

# %% [markdown]
# Estimate every contact with `lm`: on a recording (no declared target motion) it assumes
# real-ship wander and tests each track for a manoeuvre, so the one-sigma errors include the
# target's own motion.

# %%
results = tma.estimate(recording)
shown = results[["label", "time_now_utc", "range_now_m", "range_sd_m", "course_deg",
                 "course_sd_deg", "speed_m_s", "speed_sd_m_s", "status", "note"]]
print(shown.to_string(index=False))

# %% [markdown]
# A contact on a plan, and every contact on a map for Foxglove.

# %%
label = results["label"].iloc[0]
figure = tma.plot_contact(results, recording, label)
figure.savefig(out / f"{label}.png")
tma.write_map(results, recording, out / "contacts.mcap")
results.to_csv(out / "contacts.csv", index=False)
print(f"wrote {out / f'{label}.png'}, {out / 'contacts.mcap'}, {out / 'contacts.csv'}")

# %% [markdown]
# Against the AIS truth at the last bearing (when run on the bundled case).

# %%
if not given:
    row = truth.set_index("case").loc["case_11"]
    est = results.iloc[0]
    print(f"range {est.range_now_m:.0f} +- {est.range_sd_m:.0f} m (truth {row.range_m:.0f}), "
          f"course {est.course_deg:.1f} +- {est.course_sd_deg:.1f} deg "
          f"(truth {row.course_deg:.1f}), speed {est.speed_m_s:.2f} +- "
          f"{est.speed_sd_m_s:.2f} m/s (truth {row.speed_m_s:.2f})")
pd.set_option("display.width", 160)
