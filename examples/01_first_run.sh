#!/usr/bin/env bash
# %% [markdown]
# # Your first stick-slip run
#
# This tutorial runs the tutorial scene, reads its slip catalog and draws its figures. The scene
# (`configs/tutorial.yaml`) is the demo of `make demo` (`configs/demo.yaml`) loaded for 90,000 t0
# instead of 150,000, so that it slips the demo's first three slips in 60 % of its time: a layer of 1,000 dry grains, 30 d wide and about 26 d thick, under a
# normal stress of 3e-4 E (24 MPa with the thesis's material), pulled through a stiff spring
# (k = 1e-4 E/d) at V_s = 4e-5 v0. Everything is in the dimensionless units of
# {doc}`../physics/units`: lengths in grain diameters d, stresses in Young's modulus E, times in
# t0 = d / sqrt(E / rho_s).
#
# Run it. `gouge run` first compacts the loose packing under the normal stress alone, then starts
# the spring and shears the layer until `run.duration`; while it runs it detects every slip and
# keeps a checkpoint from just before each one. `--out` names the run directory (the default is
# `runs/<name>`), `--quiet` leaves out the progress bar.
# %%
gouge run configs/tutorial.yaml --out runs/first --quiet
# %% [markdown]
# The last line gives the status, the step count and the speed in grain-steps per second. The
# run directory holds the validated config, the run file and the checkpoints
# ({ref}`ref-rundir`):
# %%
ls runs/first runs/first/checkpoints
# %% [markdown]
# ## The slip catalog
#
# A slip starts when the top wall moves faster than `slips.start_factor` V_s (here 5 V_s) and
# ends when it falls back below `slips.end_factor` V_s; `gouge slips` lists what the run found.
# Times are counted from the start of loading. The static strength is the largest tau/sigma before
# the onset, the stress drop how far tau/sigma fell during the slip.
# %%
gouge slips runs/first
# %% [markdown]
# `gouge slips --json` writes the same catalog for scripts. `gouge analyze` adds the
# block-slider fit of each slip (thesis Eq. 3: the wall velocity of a rigid block on a spring is
# half a sine, lasting pi sqrt(m_b / k)) and the statistics over the run:
# %%
gouge analyze runs/first
# %% [markdown]
# ## Figures
#
# `gouge plot` draws the run overview (tau/sigma, wall velocity, layer thickness and porosity
# against time, slips shaded) and a snapshot of the grains into `runs/first/figures/`:
# %%
gouge plot runs/first
# %% [markdown]
# ![run overview](runs/first/figures/overview.png)
#
# The run file is plain HDF5: every series carries its unit and meaning ({ref}`ref-series`), so
# any HDF5 reader can pick it up:
# %%
python - <<'PY'
import h5py
with h5py.File("runs/first/run.h5", "r") as f:
    tau = f["series/tau_over_sigma"]
    print(len(tau), "rows;", tau.attrs["unit"], "-", tau.attrs["description"])
    print("largest tau/sigma:", round(float(tau[:].max()), 4))
PY
# %% [markdown]
# Next: {doc}`02_fork_pair` forks one of these slips drained and undrained.
