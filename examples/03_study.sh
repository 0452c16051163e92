#!/usr/bin/env bash
# %% [markdown]
# # The study: every slip, drained and undrained
#
# `gouge study` does what the thesis's Section 4 did by hand: a dry loading run, then a drained
# and an undrained branch of every slip that is not a start-up transient, each from the packing kept
# before that slip, the pair verdicts, and a report next to the thesis's numbers. Given a config it
# runs the loading run first; given a run directory it forks that run. Here it forks slips 2 and 3
# of the run of {doc}`01_first_run` (slip 2 was forked in {doc}`02_fork_pair`: the study finds
# its finished branches and does not run them again).
# %%
test -f runs/first/run.h5 || gouge run configs/tutorial.yaml --out runs/first --quiet
gouge study runs/first --perm 1e-5 --slips 2-3 --jobs 2 --quiet | tail -n 25
# %% [markdown]
# The study writes `runs/first/study/`: `table.csv` (one row per pair, the thesis's Table 3
# columns), `summary.json`, `report.md` (the text printed above) and `figures/`:
# %%
ls runs/first/study runs/first/study/figures | head -n 20
head -n 3 runs/first/study/table.csv | cut -c1-300
# %% [markdown]
# Running it again runs nothing that is finished; a new `--perm` adds only its branches. The
# scene of the real study is `configs/study.yaml` (2,000 grains, a soft spring, 5e6 t0 of
# loading: about half an hour on one core); its results against the thesis are on
# {doc}`../validation`:
#
# ```bash
# gouge study configs/study.yaml --perm 1e-5
# ```
