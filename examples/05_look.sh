#!/usr/bin/env bash
# %% [markdown]
# # Looking at a slip: ParaView and a movie
#
# This tutorial exports the forked slip of {doc}`02_fork_pair` for ParaView and renders it as a
# movie. The first cell makes the run and the fork if they are not there.
# %%
test -f runs/first/run.h5 || gouge run configs/tutorial.yaml --out runs/first --quiet
test -f runs/first/forks/slip_002/pair.json || gouge restart runs/first --slip 2 --perm 1e-5 --quiet > /dev/null
# %% [markdown]
# ## ParaView
#
# `gouge export` writes one VTKHDF file per run or fork branch, holding every snapshot as a time
# step (time since loading began). `--fork slip_002/perm_1e-05` picks the undrained branch of
# slip 2 (`--fork slip_002` exports every branch of that fork):
# %%
gouge export runs/first --fork slip_002/perm_1e-05
ls -la runs/first/export
# %% [markdown]
# Open the file in ParaView (File > Open; the VTKHDF reader is built in), press Apply, and the time
# slider steps through the snapshots. It holds four blocks: `grains` (one point per grain: radius,
# velocity, spin, body code, contact force), `contacts` (one line per touching pair with its normal
# and tangential force), `walls` and, for a wet branch, `pressure_grid` (the pore pressure and
# porosity per cell). Show the grains as *Point Gaussian* scaled by `radius` (uncheck *Use Scale
# Function*) and colour them by `velocity`; show the contacts as lines, or tubes of radius
# `normal_force`, to see the force chains. `--split` writes one file per block for older ParaView
# versions (VTK 9.3 / ParaView 5.12 read those).
#
# ## A movie
#
# `gouge movie` puts the drained and the undrained branch side by side: pore pressure P/sigma on one
# colour scale for the whole movie, force chains, and the wall velocity of both branches with a
# moving marker. It writes MP4 through the ffmpeg of the `imageio-ffmpeg` package (the `movie`
# extra), else an animated GIF:
# %%
gouge movie runs/first --slip 2 --perm 1e-5
# %% [markdown]
# A frame of the same kind of movie, slip 4 of the full demo (the whole movie:
# {download}`demo_slip4_movie.mp4 </figures/demo_slip4_movie.mp4>`):
#
# ```{image} /figures/demo_slip4_movie_frame.png
# :alt: a frame of the demo's slip-4 movie
# ```
#
# Forks write `output.slip_frames` (30) snapshots per predicted slip duration while their top wall
# slips; a loading run does the same with `--set output.slip_frames=30`.
