# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # gouge from Python: a run, a slip, its drained and undrained twins, and a study table
#
# This notebook opens a gouge run with the Python API (`import gouge_cli as gouge`), looks at its
# time series and slip catalog, overlays the top-wall velocity of the drained and undrained
# branches of one slip with the block-slider fit (thesis Eq. 3), and tabulates the pairs of a study.
# Every number is the one the CLI prints (`gouge slips --json`, `gouge analyze`, pair.json).
#
# It looks at the demo run, `runs/demo` (made by `make demo`, or run here if it is missing), and
# forks its second slip with a checkpoint at kappa_c = 1e-5 d^2 unless that slip has a fork
# already. (The docs and the tests point `GOUGE_TUTORIAL_RUN` and `GOUGE_TUTORIAL_SLIP` at their
# own run, and `GOUGE_TUTORIAL_FIGURES` at a folder for the figures.)

# %%
import os
from pathlib import Path

import gouge_cli as gouge
from gouge_cli.plots.axes import series, table_scatter, wall_velocity

where = Path(os.environ.get("GOUGE_TUTORIAL_RUN", "runs/demo"))
run = gouge.open_run(where) if (where / "run.h5").is_file() else gouge.run("demo", out=where)
with_checkpoint = [int(n) for n, ck in run.slips["checkpoint"].items() if ck]
slip = int(os.environ.get("GOUGE_TUTORIAL_SLIP") or with_checkpoint[min(1, len(with_checkpoint) - 1)])
if slip not in run.forks:
    gouge.restart(run, slip=slip, perm=[1e-5])


def save(ax, name):
    """Keep a figure as PNG where GOUGE_TUTORIAL_FIGURES says (nothing otherwise)."""
    if os.environ.get("GOUGE_TUTORIAL_FIGURES"):
        folder = Path(os.environ["GOUGE_TUTORIAL_FIGURES"])
        folder.mkdir(parents=True, exist_ok=True)
        ax.figure.savefig(folder / f"{name}.png", dpi=100)


run

# %% [markdown]
# ## Time series: an `xarray.Dataset`
#
# Each variable carries its unit and description from the run file; the coordinate `time` is in t0
# since loading began, `time_s` the same in seconds. Nothing but the time column is read until a
# variable is used.

# %%
ds = run.series
print(ds)
print(ds["tau_over_sigma"].attrs)

# %%
ax = series(run, ["tau_over_sigma"])
ax.set_ylabel("τ / σ")
save(ax, "series")

# %% [markdown]
# ## The slip catalog: a `pandas.DataFrame`

# %%
columns = ["onset_time", "duration", "static_strength", "stress_drop", "peak_velocity_over_Vs",
           "fit_r2", "fit_ok", "m_eff_over_m_b", "checkpoint"]
print(run.slips[columns].to_string(float_format=lambda v: f"{v:.4g}"))

# %% [markdown]
# The table is indexed by the slip number; `df.attrs["units"]` gives each column's unit (`1` for a
# dimensionless one, as pint spells it; `t0`, `d_grain`, `E`, `v0` the scales of the docs' *Units and scales* page).
# `run.to_si` converts a table or a series to SI units in one call, by the run's scales:

# %%
si = run.to_si(run.slips[["onset_time", "duration", "slip", "stress_drop", "m_eff"]])
print({column: si.attrs["units"][column] for column in si.columns})
print(si.to_string(float_format=lambda v: f"{v:.4g}"))

# %% [markdown]
# ## A grain snapshot

# %%
snap = run.snapshot(-1)
print(f"snapshot at t = {snap.attrs['time']:.6g} t0 since loading: {snap.sizes['grain']} grains, "
      f"{snap.sizes['contact']} contacts")

# %% [markdown]
# ## Drained and undrained twins of one slip, with the block-slider fit
#
# `run.pair(slip, perm)` puts both branches on one time axis and classifies them with the one pair
# definition: the type and measures below are those of the fork's `pair.json`. Every time in the
# API is counted from the start of loading, as in `run.slips` and `pair.json`; a name with `clock`
# in it is on the stored clock (which also counts the compaction).

# %%
fork = run.fork(slip)
pair = fork.pair(min(fork.undrained))
ax = wall_velocity(pair)
save(ax, "wall_velocity")
print(pair)
print(pair.measures[["type", "criteria", "drained_strength", "undrained_strength", "peak_velocity_ratio",
                     "stress_drop_ratio", "duration_ratio", "drained_onset"]].to_string())
event = pair.events["drained"]
print(f"drained compared slip: onset {event.onset_time:.1f} t0 since loading (stored clock {event.onset_clock:.1f}); "
      f"in run.slips: {run.slips.loc[slip, 'onset_time']:.1f}")

# %% [markdown]
# ## The pairs of a study: one table, ready for `groupby`

# %%
pairs = gouge.open_study(run.path)
print(pairs[["slip", "permeability", "type", "transient", "strength_difference", "peak_velocity_ratio",
             "stress_drop_ratio"]].to_string(float_format=lambda v: f"{v:.4g}"))
print(pairs.groupby(["permeability", "type"]).size())

# %%
ax = table_scatter(pairs, "permeability", "stress_drop_ratio", by="type")
save(ax, "pairs")
