#!/usr/bin/env bash
# %% [markdown]
# # A campaign on a Dask cluster, local or SLURM
#
# `gouge campaign SPEC.yaml` runs a parameter sweep: a base config, overrides at every point
# (`set`), a `sweep` (a `grid` of values, a list of `points`, `seeds`) and per point an `action`:
# `run` (the loading run) or `study` (the run, then every slip forked drained and undrained at
# `study.permeabilities`). Each piece of work is one Dask task; where it runs does not change the
# results. This tutorial sweeps the normal stress of a short demo run over two values (the spec
# goes to `runs/`, which git ignores, as do its outputs, `out: runs/campaigns`):
# %%
mkdir -p runs
cat > runs/sweep.yaml <<'YAML'
name: sigma_sweep
out: runs/campaigns
base: configs/demo.yaml
set: {run.duration: 40000}
sweep:
  grid:
    loading.normal_stress: [2.0e-4, 3.0e-4]
action: run
YAML
gouge campaign runs/sweep.yaml --workers 2
# %% [markdown]
# Each point is a run directory `<out>/<name>/<point>/` (here under `runs/campaigns/sigma_sweep/`)
# with `point.yaml` (its overrides,
# resolved config and the `gouge run` command that reproduces it bit for bit) and a ledger that
# records each piece's state. `--status` reads the ledgers and runs nothing; so does a second
# `gouge campaign` of a finished spec:
# %%
gouge campaign runs/sweep.yaml --status
# %% [markdown]
# `table.csv` has one row per run (the swept values, the number of slips, the mean and spread of
# their stress drop, peak velocity, duration, recurrence, static strength and slip) and, for
# `action: study`, one per pair ({ref}`ref-campaign-table`):
# %%
cut -d, -f1-8 runs/campaigns/sigma_sweep/table.csv
# %% [markdown]
# ## Results that outlive the machine
#
# As each piece finishes, it also writes a small record, `results/<point>/run.json` (and
# `fork_NNN.json` for each forked slip of a study): the settings it ran with and their digest,
# gouge's commit, the CPU and numba target, its table row or its pairs, and the final state hash
# ({ref}`ref-campaign-results`). The tables are built from these records alone. Copy or commit
# the results folder: a campaign started again on another machine, with the records but without
# the run folders, runs only what is not recorded. Here the run folders are deleted, and the tables
# are written again from the records (`--tables` runs nothing):
# %%
du -sh runs/campaigns/sigma_sweep/results
rm -rf runs/campaigns/sigma_sweep/normal_stress-*
gouge campaign runs/sweep.yaml --tables
# %% [markdown]
# Two results folders of one spec (say, half the seeds run on a laptop, half on a cluster)
# merge: `gouge campaign SPEC --merge OTHER/results` copies in the records this folder lacks and
# refuses, naming the key, a record of the same piece made with other settings. A campaign
# finishes points before it starts new ones (no more points in flight than the cluster has task
# slots, a point's forks before any new loading), so a lost machine costs at most the points in
# flight; a point whose forks are not all recorded runs its loading again, bit for bit (checked
# against the recorded final state hash), and then only the missing forks.
#
# ## The phase diagram
#
# `examples/campaign_phase.yaml` sweeps the demo scene over 2 normal stresses x 2 permeabilities
# with `action: study` and writes `phase_diagram.csv` and `figures/phase_diagram.png`: the
# fraction of complex and of Type II pairs in each (kappa_c, sigma) cell. On a laptop:
#
# ```bash
# gouge campaign examples/campaign_phase.yaml               # a LocalCluster on all cores
# gouge campaign examples/campaign_phase.yaml --threads 2   # 2 numba threads per task
# ```
#
# ## The same campaign on SLURM
#
# With the `cluster` extra (`pip install 'gouge[cluster]'`, for dask-jobqueue) the workers are
# SLURM jobs; each job's cores are split into workers of `--threads` numba threads, which retire
# five minutes before the walltime (a run whose job ended resumes from its checkpoint in the next
# one). The campaign folder must be on a file system the jobs share:
#
# ```bash
# gouge campaign examples/campaign_phase.yaml --slurm --slurm-cores 32 --slurm-memory 64GB \
#     --slurm-walltime 24:00:00 --slurm-queue normal --slurm-account geo123 --slurm-jobs 4 --threads 2
# ```
#
# An existing Dask cluster works too: `--scheduler tcp://HOST:8786`, its workers started as
# `NUMBA_NUM_THREADS=2 dask worker tcp://HOST:8786 --nthreads 1 --nworkers CORES/2`. A changed
# spec adds only its new points; a point whose settings changed is refused with the changed keys
# unless `--force`. Physics failures are recorded with their cause and not retried
# (`--retry-failed`).
