"""The run file ``run.h5``: its layout and its time series (SERIES). The code that writes or
reads it, one job a module: :mod:`~gouge_cli.io.runwriter` (RunFile, written while a run goes on,
add_slip its slip catalog), :mod:`~gouge_cli.io.runreader` (RunReader, RunInfo, run_status),
:mod:`~gouge_cli.io.slipcatalog` (the slip catalog's records and reader),
:mod:`~gouge_cli.io.recovery` (a resume's series tail, mending and rebuilding) and
:mod:`~gouge_cli.io.analysis_tables` (the tables of `gouge analyze`). Self-describing time
series, grain snapshots, slips, analysis tables and provenance.

Layout of ``run.h5``::

    /            attrs: config (YAML), scales (JSON), version, seed, dt, status, created,
                 provenance (JSON: version, commit, command, libraries, CPU, threads; see
                 gouge_cli.io.provenance), provenance_resumed (JSON, of the latest resume) and
                 final_state_hash (16 hex digits of the state when the run stopped),
                 stick_scaling_counts (JSON, runs with numerics.stick_scaling > 1: rollbacks, misses,
                 steps scaled / at true inertia / discarded; gouge_cli.driver.stick_scaling)
    /series/<q>  (T,) float64, resizable; attrs unit, description
    /snapshots/<step>/{x,z,radius,vx,vz,spin,body, contact_i, contact_j, contact_fx, contact_fz}
                 attrs time, load_time, step; optional pressure/porosity [nx, nz] fields when the
                 scene has fluid (attrs origin, spacing, axis_order); grains in their original
                 (packing) order, contact_i/j in those numbers
    /slips/NNN   one group per slip recorded while running (driver.slips.SlipRecorder), NNN from 001:
                 attrs = the fields of io.slipcatalog.SlipEntry but its sub-events (the
                 model.slip_rule.Slip fields onset_time, end_time, duration, slip, peak_velocity,
                 stress_drop, ..., plus number, deborah, checkpoint (path of
                 checkpoints/slip_NNN.h5 or ""), checkpoint_time); datasets subevent_time [t0],
                 subevent_velocity [v0] (S,)
    /analysis    written by `gouge analyze` (replaced on each call): attrs created, version, notch,
                 summary (JSON); groups catalog, fits[, pairs], one dataset per column
                 (analysis.catalog CATALOG_COLUMNS / FIT_COLUMNS, analysis.forkpairs PAIR_COLUMNS)
    Every dataset has unit and description attributes; attribute_units (JSON) documents the
    attributes of each group (gouge_cli.io.filedoc).

Rows are buffered and flushed every ``flush_rows`` rows or on close, so a crash loses at
most the rows since the last flush. A flush rewrites each column's last, partly filled chunk: a
kill inside that write can leave the chunk's new bytes under its old Fletcher-32, so that rows
flushed before the latest checkpoint fail their check although their bytes are intact (1 of ~400
writers killed at random). The checkpoint therefore records a digest of those rows
(:class:`~gouge_cli.io.recovery.SeriesTail`), and a resume mends such a chunk when its rows match it
(:func:`~gouge_cli.io.recovery.mend_series_tail`); anything else damaged is still refused.

Integrity (:mod:`gouge_cli.io.integrity`): series, snapshot and grid datasets are chunked with
HDF5's Fletcher-32 checksum (checked by HDF5 on every read); every group and dataset carries
``attrs_sha256``, a SHA-256 over its other attributes (and over the data of the small datasets
without Fletcher-32: slip sub-events, /analysis columns). The readers check both and the
series time for increase, and raise DamagedFileError (exit 2) naming the dataset, the rows or
the attribute; a file written before checksums (no root ``attrs_sha256``) is read unchecked.
"""

from __future__ import annotations

SERIES = {
    "time": ("t0", "simulated clock since the start of compaction (commands and figures report "
                   "time - (time[0] - load_time[0]): since loading began)"),
    "load_time": ("t0", "time since the driver started"),
    "wall_x": ("d", "top-wall displacement along the fault since the driver started"),
    "wall_z": ("d", "top-wall position across the layer (mean z of its grains)"),
    "wall_vx": ("v0", "top-wall velocity along the fault"),
    "wall_vz": ("v0", "top-wall velocity across the layer"),
    "spring_stretch": ("d", "V_s t + s0 - x_wall (s0: stretch balancing the residual shear at the start)"),
    "tau_over_sigma": ("-", "spring shear stress k (V_s t + s0 - x) / normal stress"),
    "wall_shear_stress": ("E", "grain shear force on the top wall per unit length (resisting the spring)"),
    "wall_normal_stress": ("E", "grain normal force on the top wall per unit length"),
    "thickness": ("d", "distance between the wall grain centre lines"),
    "porosity": ("-", "mean 2D porosity between the wall centre lines"),
    "kinetic_energy": ("E d^3", "translational + rotational kinetic energy of free grains"),
    "coordination": ("-", "contacts per free grain"),
    "max_overlap": ("-", "largest overlap / smaller radius of the pair"),
    "nonfinite": ("-", "grains with a non-finite coordinate or velocity"),
    "pressure_mean": ("E", "mean pore pressure perturbation"),
    "pressure_min": ("E", "smallest pore pressure perturbation"),
    "pressure_max": ("E", "largest pore pressure perturbation"),
    "deborah": ("-", "Deborah number l u0 / D: l half the layer thickness, u0 the top wall's speed |wall_vx|, "
                     "D the mean diffusivity (independent of the grid)"),
    "deborah_grid": ("-", "diagnostic: l u0 / D with u0 the largest solid speed deposited on the grid (depends on "
                          "the grid and the filter width)"),
    "fluid_energy": ("E d^3", "elastic energy stored in the pore fluid, sum of dx dz beta phi P^2 / 2 (per unit "
                              "thickness)"),
    "drag_power": ("E d^3/t0", "work rate of the fluid drag on the grains, sum of F . v"),
    "fluid_updates": ("-", "pore-pressure updates of the grid so far (cumulative)"),
    "explicit_updates": ("-", "of them, those that took the explicit step (fluid.solver auto: Heun; explicit: FTCS)"),
    # stick scaling (driver.stick_scaling), only in runs with numerics.stick_scaling > 1
    "stick_scaling": ("-", "inertia scaling lambda in force at this row (1: true inertia)"),
    "inertial_number": ("-", "I = (|v_wall| / H) d_mean sqrt(lambda rho / sigma) of the layer"),
    "stick_deborah": ("-", "stick-phase Deborah number sqrt(lambda) De (wet runs)"),
}

SERIES_CHUNK = 4096        # rows per chunk of every /series column
