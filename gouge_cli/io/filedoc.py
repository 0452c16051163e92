"""What every dataset and attribute of a run file or checkpoint means: unit and description.

HDF5 datasets carry ``unit`` and ``description`` attributes. Attributes cannot carry
attributes, so each group with attributes of its own also holds ``attribute_units``: JSON
``{name: [unit, description]}``. Units are written as pint reads them with the run's
definitions (gouge_cli.units.pint_definitions): the dimensionless '-' of the tables below is '1'.
Units are the dimensionless scales of docs/physics/units.md (length d, stress E, time
t0 = d / sqrt(E / rho_s), velocity v0 = d / t0); the SI size of each is the run file's ``scales``
attribute.

Time origin: the stored clock (``time`` series, snapshot and slip times) runs from the start
of compaction. Every command and figure reports time since loading began,
t_load = time - load_start_clock, where load_start_clock = time[0] - load_time[0] of the run
(for a fork: of its parent run, whose driver clock the fork continues).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py

from ..units import pint_unit

TIME_ORIGIN = "t0 since loading began (the driver start); stored clocks run from the start of compaction"

BODY_CODES = {0: "free grain", 1: "bottom-wall grain (fixed)", 2: "top-wall grain (moves with the spring-driven wall)"}

GRID_AXES = "array index [ix, iz]: ix along the fault (x, periodic), iz across the layer (z)"

SNAPSHOT = {
    "x": ("d", "grain centre along the fault (periodic, not wrapped into [0, width))"),
    "z": ("d", "grain centre across the layer"),
    "radius": ("d", "grain radius"),
    "vx": ("v0", "grain velocity along the fault"),
    "vz": ("v0", "grain velocity across the layer"),
    "spin": ("1/t0", "grain angular velocity about the out-of-plane axis (counter-clockwise in x-z)"),
    "body": ("-", "body code: " + ", ".join(f"{k} {v}" for k, v in BODY_CODES.items())),
    "contact_i": ("-", "first grain of each touching pair (original grain number)"),
    "contact_j": ("-", "second grain of each touching pair (original grain number)"),
    "contact_fx": ("E d^2", "x of the elastic contact force on grain j by grain i (no dashpot part)"),
    "contact_fz": ("E d^2", "z of the elastic contact force on grain j by grain i (no dashpot part)"),
    "pressure": ("E", "pore-pressure perturbation per grid cell; " + GRID_AXES),
    "porosity": ("-", "2D porosity 1 - s per grid cell (unclamped); " + GRID_AXES),
}

SNAPSHOT_ATTRS = {
    "time": ("t0", "simulated clock since the start of compaction"),
    "load_time": ("t0", "time since loading began (the time origin of every command and figure)"),
    "step": ("-", "time-step count since the start of compaction"),
}

GRID_ATTRS = {
    "origin": ("d", "[x, z] of the grid's lower-left corner (x = 0, z = bottom wall plane)"),
    "spacing": ("d", "[dx, dz] cell size; cell (ix, iz) is centred at origin + (ix + 1/2, iz + 1/2) spacing"),
    "axis_order": ("-", "what the two array indices run along"),
}

RUN_ATTRS = {
    "config": ("-", "validated, fully resolved config (YAML, dimensionless)"),
    "scales": ("-", "SI value of each unit (JSON): length_m, stress_pa, density_kg_m3, velocity_m_s, time_s"),
    "version": ("-", "gouge version that wrote the file"),
    "seed": ("-", "random seed of the packing"),
    "dt": ("t0", "DEM time step"),
    "status": ("-", "running, finished, interrupted or 'failed: <cause>'"),
    "created": ("-", "local time the file was created (ISO 8601)"),
    "units": ("-", "the unit system"),
    "n_grains": ("-", "grains, wall grains included"),
    "width": ("d", "periodic length L_x"),
    "wall_mass_per_length": ("rho_s d^2", "top-wall mass per unit length m_b"),
    "compaction_settled": ("-", "whether compaction settled within compaction.max_time"),
    "load_start_time": ("t0", "clock when this file's loading (or fork) began"),
    "end_time": ("t0", "clock at which the run (or fork) stops"),
    "deborah_mean": ("-", "mean Deborah number of the fluid over the run"),
    "deborah_max": ("-", "largest Deborah number of the fluid over the run"),
    "parent_run": ("-", "run directory this fork was started from"),
    "parent_checkpoint": ("-", "checkpoint (relative to parent_run) the fork started from"),
    "fork_slip": ("-", "number of the parent's slip this fork restarts"),
    "branch": ("-", "drained or perm_K (kappa_c = K d^2)"),
    "time_origin": ("-", "the time origin of every command and figure"),
    "body_codes": ("-", "meaning of the snapshot body codes (JSON)"),
    "snapshot_dense_interval": ("t0", "snapshot cadence during a slip (forks)"),
    "provenance": ("-", "what wrote the file (JSON): gouge version, git commit, command line, library "
                        "versions, CPU model and vector features, numba target, threads (gouge_cli.io.provenance)"),
    "provenance_resumed": ("-", "provenance (JSON) of the latest `gouge resume` that continued this run"),
    "final_state_hash": ("-", "SHA-256 (16 hex digits) of every evolving array when the run stopped"),
}

SLIP_ATTRS = {
    "number": ("-", "slip number in the run, from 1"),
    "onset_index": ("-", "series sample of the onset (in the detector's stream)"),
    "onset_time": ("t0", "clock at the onset (v_wall crosses end_factor V_s before the trigger)"),
    "end_index": ("-", "series sample of the end"),
    "end_time": ("t0", "clock at the end (v_wall back below end_factor V_s)"),
    "duration": ("t0", "end_time - onset_time"),
    "slip": ("d", "top-wall displacement during the slip"),
    "peak_velocity": ("v0", "largest top-wall velocity"),
    "peak_index": ("-", "series sample of the peak velocity"),
    "peak_time": ("t0", "clock at the peak velocity"),
    "mean_velocity": ("v0", "slip / duration"),
    "static_strength": ("-", "largest tau/sigma before the onset"),
    "tau_onset": ("-", "tau/sigma at the onset"),
    "tau_min": ("-", "smallest tau/sigma during the slip"),
    "stress_drop": ("-", "static_strength - tau_min, as tau/sigma"),
    "porosity_change": ("-", "porosity at the end minus at the onset"),
    "n_merged": ("-", "detector events merged into this slip"),
    "deborah": ("-", "mean Deborah number during the slip (NaN dry)"),
    "checkpoint": ("-", "pre-slip checkpoint, relative to the run directory ('' if none)"),
    "checkpoint_time": ("t0", "clock of the pre-slip checkpoint (NaN if none)"),
}

SLIP_DATASETS = {
    "subevent_time": ("t0", "clock of each local velocity maximum inside the slip"),
    "subevent_velocity": ("v0", "top-wall velocity at each sub-event"),
}

CHECKPOINT = {
    "state/id": ("-", "original grain number of each current slot (grains are re-numbered in place)"),
    "state/x": SNAPSHOT["x"], "state/z": SNAPSHOT["z"], "state/vx": SNAPSHOT["vx"], "state/vz": SNAPSHOT["vz"],
    "state/spin": SNAPSHOT["spin"],
    "state/force_x": ("E d^2", "total force on each grain along x"),
    "state/force_z": ("E d^2", "total force on each grain along z"),
    "state/torque": ("E d^3", "torque on each grain"),
    "state/start": ("-", "neighbour-list row starts (CSR), current grain numbering"),
    "state/index": ("-", "neighbour-list partner of each listed pair"),
    "state/shear": ("d", "tangential spring displacement of each listed pair (Mindlin history)"),
    "state/x_build": ("d", "x of each grain when the neighbour list was built"),
    "state/z_build": ("d", "z of each grain when the neighbour list was built"),
    "state/wall": ("d, v0, E d^2", "top wall [x, z, vx, vz, fx, fz] (kernels.step W_*)"),
    "state/clock": ("t0, t0, d", "[time since compaction start, time since loading began, spring anchor s0]"),
    "state/counters": ("-", "[step, rebuilds, pairs, need_rebuild, needed_capacity, phase] (kernels.step K_*)"),
    "fluid/pressure": SNAPSHOT["pressure"],
    "fluid/solid_fraction": ("-", "solid fraction s = 1 - porosity per grid cell; " + GRID_AXES),
    "fluid/state": ("d, -", "fluid kernel state vector (kernels.layout S_*; S_Z_BOT, S_Z_TOP: wall planes [d])"),
    "fluid/drag_x": ("E d^2", "fluid drag on each grain along x (Eq. 12)"),
    "fluid/drag_z": ("E d^2", "fluid drag on each grain along z (Eq. 12)"),
}

CHECKPOINT_ATTRS = {
    "config": RUN_ATTRS["config"],
    "extra": ("-", "JSON: the header (phase, slips recorded, series tail; slip number and onset time of a "
                   "slip checkpoint) and, under 'states', each callback's state by name (slip detector, guards, "
                   "stick scaling, compaction's start)"),
    "version": RUN_ATTRS["version"],
    "checksum": ("-", "'sha256-v2:' + SHA-256 over every dataset (path, dtype, shape, bytes) and every "
                      "attribute of the file but this one"),
    "provenance": RUN_ATTRS["provenance"],
}


_T0 = ("onset_time", "end_time", "onset_clock", "duration", "recurrence", "half_period", "predicted_half_period")
# units of the slip tables' columns (catalog, fits; '-' where absent); the pairs table's are
# analysis.forkpairs PAIR_UNITS, passed to write_analysis_tables
ANALYSIS_UNITS = dict({k: "t0" for k in _T0}, slip="d", peak_velocity_over_Vs="V_s", mean_velocity_over_Vs="V_s",
                      amplitude_over_Vs="V_s", pressure_min_over_sigma="sigma", pressure_max_over_sigma="sigma",
                      static_strength="sigma", stress_drop="sigma", m_eff_over_m_b="m_b",
                      notch_frequency="1/t0", onset_time_s="s", duration_s="s", half_period_s="s", slip_m="m",
                      stress_drop_MPa="MPa", peak_velocity_m_s="m/s")
ANALYSIS_ATTRS = {
    "created": RUN_ATTRS["created"], "version": RUN_ATTRS["version"],
    "notch": ("-", "whether mu_d(t) was notch-filtered"),
    "summary": ("-", "JSON: parameters, statistics over all slips, fit summary, campaign counts"),
    "columns": ("-", "JSON list of the table's columns, in order"),
}


def document_analysis(group, units: dict[str, dict[str, str]] | None = None) -> None:
    """unit/description of the /analysis tables `gouge analyze` writes into run.h5 (one dataset
    per column; unit '-' for ratios, counts, flags and labels). `units`: {table: {column: unit}}
    (ANALYSIS_UNITS for a table not in it); None: a column already described keeps its unit."""
    describe(group, "-", "tables written by `gouge analyze` (also RUN/analysis/*.csv)")
    describe_attributes(group, ANALYSIS_ATTRS)
    for table, g in group.items():
        describe(g, "-", f"the {table} table, one row per {'pair' if table == 'pairs' else 'slip'}")
        describe_attributes(g, ANALYSIS_ATTRS)
        table_units = (units or {}).get(table, ANALYSIS_UNITS)
        for name, ds in g.items():
            if units is None and "unit" in ds.attrs:
                continue
            describe(ds, table_units.get(name, "-"), f"column {name} of RUN/analysis/{table}.csv")


def json_safe(obj):
    """Copy of ``obj`` that json.dumps writes as valid JSON: NaN/inf become null, paths and
    numpy scalars/arrays plain values, tuples lists."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):
        obj = obj.tolist()
        if isinstance(obj, list):
            return json_safe(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def describe(obj, unit: str, description: str) -> None:
    """Set the ``unit`` and ``description`` attributes of an HDF5 dataset or group."""
    obj.attrs["unit"] = pint_unit(unit)
    obj.attrs["description"] = description


def describe_attributes(group, table: dict) -> None:
    """Write ``attribute_units`` (JSON {name: [unit, description]}) for the group's own attributes."""
    known = {k: table.get(k, ("-", "undocumented")) for k in group.attrs.keys()
             if k not in ("attribute_units", "unit", "description", "attrs_sha256")}     # the seal: io.integrity
    group.attrs["attribute_units"] = json.dumps({k: [pint_unit(u), text] for k, (u, text) in known.items()})


def grid_geometry(z_bottom: float, dx: float, dz: float) -> dict:
    """Attributes of a cell-centred [nx, nz] field: origin, spacing and axis order."""
    return {"origin": [0.0, float(z_bottom)], "spacing": [float(dx), float(dz)], "axis_order": "x, z"}


def document_run_file(h5: h5py.File) -> None:
    """Fill in the unit, description and attribute_units of everything in an open run file
    (what the writer described already keeps its text)."""
    h5.attrs["time_origin"] = TIME_ORIGIN
    h5.attrs["body_codes"] = json.dumps(BODY_CODES)
    describe_attributes(h5, RUN_ATTRS)
    for name, text in (("series", "time series, one row per series_interval"),
                       ("snapshots", "grain snapshots, one group per step (12-digit name)"),
                       ("slips", "slip catalog, one group per slip (3-digit number)")):
        if name in h5 and "unit" not in h5[name].attrs:
            describe(h5[name], "-", text)
    for snap in (h5["snapshots"].values() if "snapshots" in h5 else []):
        if "attribute_units" in snap.attrs:          # described when written
            continue
        for key, ds in snap.items():
            if "unit" not in ds.attrs:
                describe(ds, *SNAPSHOT.get(key, ("-", "undocumented")))
        describe_attributes(snap, SNAPSHOT_ATTRS)
    for slip in (h5["slips"].values() if "slips" in h5 else []):
        document_slip(slip)

    if "analysis" in h5:
        document_analysis(h5["analysis"])


def document_slip(group) -> None:
    """unit/description of a /slips/NNN group's datasets and its attribute_units."""
    for key, ds in group.items():
        describe(ds, *SLIP_DATASETS.get(key, ("-", "undocumented")))
    describe_attributes(group, SLIP_ATTRS)


def document_checkpoint(h5: h5py.File) -> None:
    """unit/description on every checkpoint dataset and attribute_units for its attributes."""
    for group in ("state", "fluid"):
        for name, ds in (h5[group].items() if group in h5 else []):
            describe(ds, *CHECKPOINT.get(f"{group}/{name}", ("-", "undocumented")))
    for key, child in (h5["attached"].items() if "attached" in h5 else []):
        # a state kept with this one (the slip recorder's pre-slip ring): same layout
        describe(child, "-", f"attached state {key} (the slip recorder's ring of pre-slip states)")
        describe_attributes(child, {"extra": ("-", "callback state of the attached state (JSON)")})
        for group in ("state", "fluid"):
            for name, ds in (child[group].items() if group in child else []):
                describe(ds, *CHECKPOINT.get(f"{group}/{name}", ("-", "undocumented")))
    describe_attributes(h5, CHECKPOINT_ATTRS)
