"""HDF5 run file: self-describing time series, grain snapshots and provenance.

Layout of ``run.h5``::

    /            attrs: config (YAML), scales (JSON), version, seed, dt, status, created,
                 provenance (JSON: version, commit, command, libraries, CPU, threads; see
                 gouge_cli.provenance), provenance_resumed (JSON, of the latest resume) and
                 final_state_hash (16 hex digits of the state when the run stopped)
    /series/<q>  (T,) float64, resizable; attrs unit, description
    /snapshots/<step>/{x,z,radius,vx,vz,spin,body, contact_i, contact_j, contact_fx, contact_fz}
                 attrs time, load_time, step; optional pressure/porosity [nx, nz] fields when the
                 scene has fluid (attrs origin, spacing, axis_order); grains in their original
                 (packing) order, contact_i/j in those numbers
    Every dataset has unit and description attributes; attribute_units (JSON) documents the
    attributes of each group (gouge_cli.filedoc).

Rows are buffered and flushed every ``flush_rows`` rows or on close, so a crash loses at
most the rows since the last flush and never corrupts earlier ones.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import h5py
import numpy as np

from . import __version__, provenance
from .config import Config, dump_config
from .filedoc import SNAPSHOT, SNAPSHOT_ATTRS, describe, describe_attributes, document_run_file, grid_geometry
from .kernels import measure as M
from .kernels import step as K

# name -> (unit, description); units are the dimensionless scales of physics.md section 1
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
    "deborah": ("-", "Deborah number l u0 / D of the fluid"),
}
from .stick_scaling import SERIES_COLUMNS as _STICK     # noqa: E402  stick scaling: its columns
SERIES.update(_STICK)


class RunFile:
    """Append-only writer of one run file."""

    def __init__(self, path: Path, config: Config, dt: float, extra_attrs: dict | None = None,
                 flush_rows: int = 200, mode: str = "w", threads: int | None = None):
        self.path = Path(path)
        self.flush_rows = flush_rows
        self._rows: list[dict] = []
        self.h5 = h5py.File(self.path, mode)
        if mode == "w":
            a = self.h5.attrs
            a["config"] = dump_config(config)
            a["scales"] = json.dumps(config.scales.scales().as_dict())
            a["version"] = __version__
            a["seed"] = config.seed
            a["dt"] = dt
            a["status"] = "running"
            a["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
            a["units"] = "dimensionless: length d, stress E, time t0 = d/sqrt(E/rho_s); see scales"
            a["provenance"] = provenance.dumps(provenance.collect(threads))
            for key, value in (extra_attrs or {}).items():
                a[key] = value
            self.h5.create_group("series")
            self.h5.create_group("snapshots")
        else:
            self.h5.attrs["provenance_resumed"] = provenance.dumps(provenance.collect(threads))

    def append(self, row: dict):
        self._rows.append(row)
        if len(self._rows) >= self.flush_rows:
            self.flush()

    def flush(self):
        if self._rows:
            group = self.h5["series"]
            names = list(dict.fromkeys(n for r in self._rows for n in r if n in SERIES))
            rows_before = group["time"].shape[0] if "time" in group else 0
            for name in names:     # a column missing from some rows (stick scaling's) is NaN there
                values = np.array([r.get(name, np.nan) for r in self._rows], dtype=np.float64)
                if name not in group:
                    unit, description = SERIES[name]
                    ds = group.create_dataset(name, shape=(0,), maxshape=(None,), dtype=np.float64,
                                              chunks=(4096,))
                    ds.attrs["unit"] = unit
                    ds.attrs["description"] = description
                    if name != "time" and rows_before:
                        ds.resize((rows_before,))
                        ds[:] = np.nan
                ds = group[name]
                old = ds.shape[0]
                ds.resize((old + values.size,))
                ds[old:] = values
            self._rows.clear()
        self.h5.flush()

    def truncate_after(self, time_limit: float, step_limit: int, slip_count: int):
        """Drop series rows after time_limit, snapshots after step_limit and catalog entries
        numbered above slip_count (resume: they are produced again)."""
        self.flush()
        group = self.h5["series"]
        if "time" in group:
            keep = int(np.searchsorted(group["time"][...], time_limit, side="right"))
            for name in group:
                group[name].resize((keep,))
        for name in list(self.h5["snapshots"]):
            if int(name) > step_limit:
                del self.h5["snapshots"][name]
        if "slips" in self.h5:
            for name in list(self.h5["slips"]):
                if int(name) > slip_count:
                    del self.h5["slips"][name]
        self.h5.flush()

    def snapshot(self, sim):
        s = sim.state
        if f"{s.step:012d}" in self.h5["snapshots"]:      # a dense (slip) and a regular snapshot coincide
            return
        grp = self.h5["snapshots"].create_group(f"{s.step:012d}")
        grp.attrs["time"] = s.time
        grp.attrs["load_time"] = float(s.clock[K.C_DRIVE_TIME])
        grp.attrs["step"] = s.step
        for name in ("x", "z", "radius", "vx", "vz", "spin", "body"):     # in original grain order
            grp.create_dataset(name, data=s.by_id(getattr(s, name)), compression="gzip", compression_opts=1)
        npairs = int(s.start[-1])
        ci = np.empty(npairs, np.int32)
        cj = np.empty(npairs, np.int32)
        cfx = np.empty(npairs)
        cfz = np.empty(npairs)
        p = sim.params
        m = M.contact_list(s.x, s.z, s.radius, s.start, s.index, s.shear, s.width, p[K.C_NORMAL],
                           p[K.C_TANGENTIAL], p[K.FRICTION], ci, cj, cfx, cfz)
        ci[:m] = s.id[ci[:m]]
        cj[:m] = s.id[cj[:m]]
        for name, arr in (("contact_i", ci), ("contact_j", cj), ("contact_fx", cfx), ("contact_fz", cfz)):
            grp.create_dataset(name, data=arr[:m], compression="gzip", compression_opts=1)
        if sim.fluid is not None:
            f = sim.fluid
            geometry = grid_geometry(f.state[f.kernels.S_Z_BOT], f.dx, f.dz)
            for name, arr in f.snapshot_fields().items():
                grp.create_dataset(name, data=arr).attrs.update(geometry)
        for name, ds in grp.items():
            describe(ds, *SNAPSHOT[name])
        describe_attributes(grp, SNAPSHOT_ATTRS)
        self.h5.flush()

    def set_attr(self, key: str, value):
        self.h5.attrs[key] = value

    def close(self, status: str = "finished", final_state_hash: str | None = None):
        if self.h5.id.valid:
            self.flush()
            if final_state_hash is not None:
                self.h5.attrs["final_state_hash"] = final_state_hash
            if "deborah" in self.h5["series"]:
                deborah = self.h5["series/deborah"][...]
                if deborah.size:
                    self.h5.attrs["deborah_mean"] = float(np.nanmean(deborah))
                    self.h5.attrs["deborah_max"] = float(np.nanmax(deborah))
            self.h5.attrs["status"] = status
            document_run_file(self.h5)
            self.h5.close()


def read_series(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as h5:
        return {name: ds[...] for name, ds in h5["series"].items()}
