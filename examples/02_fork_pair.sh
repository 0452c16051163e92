#!/usr/bin/env bash
# %% [markdown]
# # Forking a slip drained and undrained
#
# The thesis compares one earthquake twice, from the same grain packing: once with the pore fluid
# free to flow (drained) and once with a low permeability (undrained). `gouge restart` does this
# from the checkpoint the run kept just before a slip. This tutorial uses the run of
# {doc}`01_first_run`; the first cell makes it if it is not there.
# %%
test -f runs/first/run.h5 || gouge run configs/tutorial.yaml --out runs/first --quiet
# %% [markdown]
# Fork slip 2 with an undrained branch at kappa_c = 1e-5 d^2 (the thesis's "Permeability 1e-5";
# {doc}`../physics/fluid`). The drained branch is the dry model: it retraces the loading run's slip
# bit for bit. Each branch stops when its first slip ends. With `--perm`, the fork also writes
# `pair.json`, the verdict on the pair. The command prints one line per branch (its first slip's
# onset, strength, stress drop and peak velocity) and one per pair (its type, S_u - S_d and the two
# onsets it compares):
# %%
gouge restart runs/first --slip 2 --perm 1e-5 --quiet
# %% [markdown]
# The whole record is in `pair.json` (`--json` prints it too); the pair's entry:
# %%
python -c "import json; r = json.load(open('runs/first/forks/slip_002/pair.json')); print(json.dumps(r['pairs'][0], indent=1)[:1500])"
# %% [markdown]
# ## Reading the pair
#
# The pair's `type` compares the static strengths of the two branches
# ({doc}`../physics/pairs`): Type I when the undrained branch is weaker by more than 1e-3 in
# tau/sigma, Type II when it is stronger, a tie otherwise; `-C` is added when the undrained slip is
# complex (several sub-events, a restart, creep, or a poor block-slider fit), and `criteria` says
# which rule made it so. The ratios compare undrained to drained: a `peak_velocity_ratio` below 1
# means the undrained slip was slower.
#
# The branches are run directories of their own under `runs/first/forks/slip_002/`:
# %%
ls runs/first/forks/slip_002
# %% [markdown]
# ## The pair figure
#
# `gouge plot --slip 2` draws the slip of the loading run and, since it has been forked, the two
# branches side by side with the pore pressure:
# %%
gouge plot runs/first --slip 2
# %% [markdown]
# ![slip 2, drained and undrained](runs/first/figures/slip_002_pair_perm_1e-05.png)
#
# From here: {doc}`03_study` forks every slip of a run at once and compares the statistics with
# the thesis; {doc}`../howto/fork_every_slip` does the same from a shell script.
