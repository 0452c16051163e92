"""The run file ``run.h5``: the only code that writes or reads it (RunFile writes while a run goes
on, add_slip its slip catalog, write_analysis_tables the tables of `gouge analyze`; RunReader
reads it, and gouge_cli.io.slipcatalog its slip catalog). Self-describing time series, grain snapshots, slips,
analysis tables and provenance.

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
                 attrs = model.slip_rule.Slip fields (onset_time, end_time, duration, slip,
                 peak_velocity, stress drop, ...) plus number, deborah, checkpoint (path of
                 checkpoints/slip_NNN.h5 or ""), checkpoint_time; datasets subevent_time [t0],
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
(:class:`SeriesTail`), and a resume mends such a chunk when its rows match it
(:func:`mend_series_tail`); anything else damaged is still refused.

Integrity (:mod:`gouge_cli.io.integrity`): series, snapshot and grid datasets are chunked with
HDF5's Fletcher-32 checksum (checked by HDF5 on every read); every group and dataset carries
``attrs_sha256``, a SHA-256 over its other attributes (and over the data of the small datasets
without Fletcher-32: slip sub-events, /analysis columns). The readers here check both and the
series time for increase, and raise DamagedFileError (exit 2) naming the dataset, the rows or
the attribute; a file written before checksums (no root ``attrs_sha256``) is read unchecked.
"""

from __future__ import annotations

import errno
import hashlib
import json
import math
import os
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import h5py
import numpy as np
import yaml

from .. import __version__
from . import provenance
from ..config import Config, dump_config
from ..errors import DamagedFileError, NoSpaceError, NotARunError, RunStillRunningError
from ..model.slip_rule import SlipRule
from ..model.timestep import half_period
from .filedoc import (SNAPSHOT, SNAPSHOT_ATTRS, describe, describe_attributes, document_analysis, document_run_file,
                      document_slip, grid_geometry)
from ..kernels import layout as L
from .integrity import SEAL, STRUCTURE_ERRORS, attr_value, check_seal, read, seal, seal_tree, stored_seal, structure_error
from .layout import RUN_FILE, RunLayout
from .outputs import free_bytes, is_no_space, preallocate, remove_temps, require_space, temporary
from .rundir import RESERVE_BYTES
from .slipcatalog import SlipEntry
from ..units import pint_unit

# name -> (unit, description); units are the dimensionless scales of docs/physics/units.md
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


def _rows_digest(values: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(values, dtype="<f8").tobytes()).hexdigest()


@dataclass(frozen=True)
class SeriesTail:
    """What a checkpoint records of the series it lines up with: `rows` flushed rows, and per
    column the SHA-256 of its rows in the last, partly filled chunk ([start, rows), the only rows
    before the checkpoint that a later flush rewrites; empty when rows fill whole chunks)."""

    rows: int
    digests: dict = field(default_factory=dict)

    KEY = "series_tail"         # its key in a checkpoint's extra

    @property
    def start(self) -> int:
        return self.rows - self.rows % SERIES_CHUNK

    @classmethod
    def from_extra(cls, extra: dict) -> "SeriesTail | None":
        record = extra.get(cls.KEY)
        return None if record is None else cls(int(record["rows"]), dict(record["digests"]))

    def as_extra(self) -> dict:
        return {self.KEY: asdict(self)}


def torn_series_tail(path: Path, tail: SeriesTail | None) -> dict[str, tuple[bytes, np.ndarray]]:
    """The series columns of run file `path` (read only) whose chunk holding rows
    [tail.start, tail.rows) fails its Fletcher-32 while those rows' bytes match the checkpoint's
    digest: a flush after the checkpoint stopped inside its write (module doc). name -> (the
    chunk's bytes without the checksum, the tail's rows). A column whose rows do not match, or
    whose chunk cannot be read raw, is not in it (it is damaged, and refused by the resume)."""
    if tail is None or not tail.digests:
        return {}
    start, count = tail.start, tail.rows - tail.start
    torn = {}
    with h5py.File(path, "r") as h5:
        for name, digest in tail.digests.items():
            ds = h5["series"].get(name)
            if ds is None or ds.shape[0] < tail.rows or ds.dtype != np.dtype("<f8") or ds.chunks != (SERIES_CHUNK,):
                continue
            try:
                ds[start:tail.rows]
                continue                            # sound
            except OSError:
                pass
            try:
                mask, raw = ds.id.read_direct_chunk((start,))
            except (OSError, RuntimeError, ValueError):
                continue
            if mask != 0 or len(raw) != SERIES_CHUNK * 8 + 4:   # (the data and its Fletcher-32)
                continue
            values = np.frombuffer(raw, "<f8", count=count)
            if _rows_digest(values) == digest:
                torn[name] = (raw[:-4], values.copy())
    return torn


def mend_series_tail(path: Path, tail: SeriesTail | None) -> list[str]:
    """Mend the torn_series_tail columns of run file `path` (opened for writing only if there is
    one): the chunk's bytes written back unfiltered, then the tail's rows once more through HDF5,
    which checksums them anew. Returns the mended columns' names."""
    torn = torn_series_tail(path, tail)
    if torn:
        with h5py.File(path, "r+", rdcc_nbytes=0) as h5:
            for name, (data, _) in torn.items():        # Fletcher-32 marked as not applied
                h5["series"][name].id.write_direct_chunk((tail.start,), data, filter_mask=1)
        with h5py.File(path, "r+", rdcc_nbytes=0) as h5:    # (a new handle: the old one keeps the former mask)
            for name, (_, values) in torn.items():
                h5["series"][name][tail.start:tail.rows] = values
    return sorted(torn)


def _copy_attributes(src, dst) -> None:
    for name in src.attrs:         # (each with its stored type, so the seals still match)
        dst.attrs.create(name, src.attrs[name], dtype=src.attrs.get_id(name).dtype)


def rebuild_openable(path: Path, next_step: str) -> None:
    """Replace run file `path` by a copy of every object in it that can be opened (HDF5's object
    copy: attributes, seals, chunks and checksums as they were), written to a temporary file
    renamed onto `path` when complete. For a file holding, after its checkpoint, an object that
    cannot be opened (a kill inside an HDF5 flush can leave a link to an object header past the end
    the file records): HDF5 cannot delete such a link, so truncate_after could not drop it; it
    trims the copy instead. Only after the resume's check (nothing it keeps fails to open)."""
    path = Path(path)
    remove_temps(path)
    require_space(path.parent, path.stat().st_size, f"rebuilding {path}", next_step)
    with temporary(path, next_step) as tmp:
        with h5py.File(path, "r") as src, h5py.File(tmp, "w", rdcc_nbytes=0) as dst:
            _copy_attributes(src, dst)
            for group in src:                      # (series, snapshots, slips: groups of objects)
                out = dst.create_group(group)
                _copy_attributes(src[group], out)
                for name in src[group]:
                    try:
                        src.copy(src[group][name], out)
                    except STRUCTURE_ERRORS:        # (what the resume drops)
                        continue


class RunFile:
    """Append-only writer of one run file."""

    def __init__(self, path: Path, config: Config, dt: float, extra_attrs: dict | None = None,
                 flush_rows: int = 200, mode: str = "w", threads: int | None = None, safe_close: bool = True):
        self.path = Path(path)
        self.safe_close = safe_close        # False: the file is a temporary, renamed once closed (forks)
        self.flush_rows = flush_rows
        self._rows: list[dict] = []
        self._allocated = 0         # the end of the blocks allocated past HDF5's end (_room) [bytes]
        # no raw-data chunk cache: a chunk is written by the call that fills it, so a full disk
        # raises there (handled: the file closed on its reserve) and not later, when a
        # dataset handle is freed, where HDF5's error is ignored and the file's state is lost
        # (a segmentation fault followed)
        if mode == "w":     # created whole under a temporary name: no moment leaves a half-written run.h5
            with temporary(self.path) as tmp, h5py.File(tmp, "w", rdcc_nbytes=0) as h5:
                a = h5.attrs
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
                seal(h5.create_group("series"))
                seal(h5.create_group("snapshots"))
                seal(h5)
            self.h5 = h5py.File(self.path, "a", rdcc_nbytes=0)
        else:
            self.h5 = h5py.File(self.path, mode, rdcc_nbytes=0)
            self.set_attr("provenance_resumed", provenance.dumps(provenance.collect(threads)))

    def append(self, row: dict):
        self._rows.append(row)
        if len(self._rows) >= self.flush_rows:
            self.flush()

    def _room(self, need: int = 0):
        """Before an HDF5 write of about `need` bytes: the blocks HDF5 writes into next, `need` and
        a reserve of RESERVE_BYTES past its end, are allocated in the file itself
        (io.outputs.preallocate), so neither this write nor a close after it can meet a full disk,
        whatever else fills the disk meanwhile (HDF5 can neither flush nor close a file again after
        a flush that met a full disk: its status stayed 'running', and a reserve held in a file
        beside it, released for the close, could be taken by another writer, which left the file
        unreadable). OSError (ENOSPC) when the room is not there, before anything is written. Where
        the file system cannot allocate, the free space is checked instead."""
        start, room = self.h5.id.get_filesize(), need + RESERVE_BYTES
        if start + room <= self._allocated:
            return
        for ahead in (room + RESERVE_BYTES, room):    # a reserve more at once, so most writes need no call
            try:
                allocated = preallocate(self.path, ahead, start=start)
            except OSError as exc:
                if not is_no_space(exc):
                    raise
                continue
            if allocated:
                self._allocated = start + ahead
                return
            if free_bytes(self.path.parent) >= room:        # (a file system that cannot allocate)
                return
            break
        free = free_bytes(self.path.parent)
        raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)} ({free / 1e6:.1f} MB free)", str(self.path))

    def flush(self, room: bool = True):
        if room:
            self._room(64 * len(SERIES) * len(self._rows))
        if self._rows:
            group = self.h5["series"]
            names = list(dict.fromkeys(n for r in self._rows for n in r if n in SERIES))
            rows_before = group["time"].shape[0] if "time" in group else 0
            try:
                self._append_rows(group, names, rows_before)
            except BaseException:
                # (a full disk): these rows follow the last checkpoint, so a resume computes them
                # again; every column goes back to the rows it had, none left half appended
                self._rows.clear()
                for name in group:
                    try:
                        group[name].resize((rows_before,))
                    except (OSError, RuntimeError, ValueError):
                        pass
                raise
            self._rows.clear()
        self.h5.flush()

    def _append_rows(self, group, names: list[str], rows_before: int):
        """The pending rows appended to the series columns `names` of `group` (rows_before each)."""
        for name in names:     # a column missing from some rows (stick scaling's) is NaN there
            values = np.array([r.get(name, np.nan) for r in self._rows], dtype=np.float64)
            if name not in group:
                unit, description = SERIES[name]
                ds = group.create_dataset(name, shape=(0,), maxshape=(None,), dtype=np.float64,
                                          chunks=(SERIES_CHUNK,), fletcher32=True)
                ds.attrs["unit"] = pint_unit(unit)
                ds.attrs["description"] = description
                seal(ds)
                if name != "time" and rows_before:
                    ds.resize((rows_before,))
                    ds[:] = np.nan
            ds = group[name]
            old = ds.shape[0]
            ds.resize((old + values.size,))
            ds[old:] = values

    def series_tail(self) -> SeriesTail:
        """The SeriesTail of the rows flushed so far (read back from the file; after flush())."""
        group = self.h5["series"]
        rows = group["time"].shape[0] if "time" in group else 0
        start = SeriesTail(rows).start
        return SeriesTail(rows, {name: _rows_digest(ds[start:rows]) for name, ds in group.items()} if rows > start else {})

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
        grains = {name: s.by_id(getattr(s, name)) for name in ("x", "z", "radius", "vx", "vz", "spin", "body")}
        contacts = dict(zip(("contact_i", "contact_j", "contact_fx", "contact_fz"), sim.contacts()))
        fields = {}
        if sim.fluid is not None:
            f = sim.fluid
            geometry = grid_geometry(f.state[L.S_Z_BOT], f.dx, f.dz)
            fields = f.snapshot_fields()
        self._room(sum(a.nbytes for part in (grains, contacts, fields) for a in part.values()) + 100_000)
        grp = self.h5["snapshots"].create_group(f"{s.step:012d}")
        grp.attrs["time"] = s.time
        grp.attrs["load_time"] = float(s.clock[L.C_DRIVE_TIME])
        grp.attrs["step"] = s.step
        for name, arr in {**grains, **contacts}.items():     # grains in original grain order
            _checked(grp, name, arr, compression="gzip", compression_opts=1)
        for name, arr in fields.items():
            _checked(grp, name, arr).attrs.update(geometry)
        for name, ds in grp.items():
            describe(ds, *SNAPSHOT[name])
            seal(ds)
        describe_attributes(grp, SNAPSHOT_ATTRS)
        seal(grp)
        self.h5.flush()

    def add_slip(self, entry: SlipEntry):
        """Write `entry` as /slips/NNN (NNN its number): its attrs() as attributes, subevent_time and
        subevent_velocity (S,) datasets [t0, v0]; flushed at once."""
        self._room()
        if "slips" not in self.h5:
            seal(self.h5.create_group("slips"))
        group = self.h5["slips"].create_group(f"{entry.number:03d}")
        for key, value in entry.attrs().items():
            group.attrs[key] = value
        for key in entry.SUBEVENTS:
            _checked(group, key, np.array(getattr(entry, key), float))
        document_slip(group)
        for ds in group.values():
            seal(ds)
        seal(group)
        self.h5.flush()

    def set_attr(self, key: str, value):
        self.set_attrs({key: value})

    def set_attrs(self, attrs: dict):
        """Root attributes, written so that a kill at any moment leaves run.h5 whole: the rows
        flushed, the attributes written into a copy of the file renamed over it once complete
        (HDF5 grows the root's header for a new attribute, and a kill between those writes left
        the file unopenable), then the file reopened to append. In place where the file is itself
        a temporary (``safe_close=False``) or the disk has no room for the copy."""
        if self.safe_close:
            self.flush(room=False)
            self.h5.flush()
            self.h5.close()
            try:
                self._in_a_copy(lambda h5: self._write_attrs(h5, attrs))
                return
            except (OSError, RuntimeError) as exc:
                if not (isinstance(exc, NoSpaceError) or is_no_space(exc)):
                    raise
            finally:
                self.h5 = h5py.File(self.path, "a", rdcc_nbytes=0)
        self._write_attrs(self.h5, attrs)

    @staticmethod
    def _write_attrs(h5, attrs: dict):
        for key, value in attrs.items():
            h5.attrs[key] = value
        seal(h5)

    def _in_a_copy(self, write):
        """``write(h5)`` into a copy of the closed run file, renamed over it when complete."""
        with temporary(self.path) as tmp:
            require_space(self.path.parent, self.path.stat().st_size + RESERVE_BYTES, "a copy of the run file")
            shutil.copyfile(self.path, tmp)
            with h5py.File(tmp, "r+", rdcc_nbytes=0) as h5:
                write(h5)
            _trim(tmp)

    def close(self, status: str = "finished", final_state_hash: str | None = None, full_disk: bool = False):
        """Write the final attributes and close. ``full_disk``: the rows not yet written are
        dropped (they follow the last checkpoint: a resume makes them again) and the close writes
        into the reserve allocated past the file's end (_room)."""
        if full_disk:
            self._rows.clear()
        try:
            self._close(status, final_state_hash)
        except (OSError, RuntimeError):
            if not full_disk:
                raise
            self._status_anew(status)

    def _status_anew(self, status: str):
        """The status written through a new handle, when the disk filled during an HDF5 write after
        the space check (HDF5 then cannot flush or close this handle again): the handle is dropped
        and the file opened anew for its status and seal alone (its rows after the last checkpoint
        may be lost: a resume makes them again). Raises the OSError if even that fails."""
        try:
            self.h5.close()
        except (OSError, RuntimeError):
            pass
        with h5py.File(self.path, "r+", rdcc_nbytes=0) as h5:
            h5.attrs["status"] = status
            seal(h5)

    def _close(self, status: str, final_state_hash: str | None):
        """Flush the rows, then write the closing attributes (status, final state hash, De summary,
        descriptions, seals) into a copy of the flushed file that is renamed over run.h5 once
        complete (``safe_close``): a kill or power loss at any moment leaves either the file as its
        last flush left it (status 'running': `gouge resume` closes it from the final checkpoint)
        or the closed file, never a file whose closing metadata HDF5 wrote only in part. Where the
        copy finds no room (or the file is already a temporary, ``safe_close=False``), in place."""
        if not self.h5.id.valid:
            return
        self.flush(room=False)
        if not self.safe_close:
            self._closing_attrs(self.h5, status, final_state_hash)
            self.h5.close()
            _trim(self.path)
            return
        self.h5.flush()
        self.h5.close()
        try:
            self._in_a_copy(lambda h5: self._closing_attrs(h5, status, final_state_hash))
        except (OSError, RuntimeError) as exc:
            if not (isinstance(exc, NoSpaceError) or is_no_space(exc)):
                raise
            with h5py.File(self.path, "r+", rdcc_nbytes=0) as h5:        # no room for a copy: in place
                self._closing_attrs(h5, status, final_state_hash)
            _trim(self.path)

    @staticmethod
    def _closing_attrs(h5, status: str, final_state_hash: str | None):
        if final_state_hash is not None:
            h5.attrs["final_state_hash"] = final_state_hash
        if "deborah" in h5["series"]:
            deborah = h5["series/deborah"][...]
            if deborah.size:
                h5.attrs["deborah_mean"] = float(np.nanmean(deborah))
                h5.attrs["deborah_max"] = float(np.nanmax(deborah))
        h5.attrs["status"] = status
        document_run_file(h5)
        for name in ("series", "snapshots", "slips"):      # described here the first time
            if name in h5:
                seal(h5[name])
        h5.visititems(lambda _, obj: None if SEAL in obj.attrs else seal(obj))   # from before seals
        seal(h5)


def _trim(path: Path):
    """Opened and closed again, HDF5 trims the file to its end (the reserve past it: RunFile._room)."""
    try:
        h5py.File(path, "a", rdcc_nbytes=0).close()
    except (OSError, RuntimeError):
        pass


def _checked(group, name: str, data: np.ndarray, **options):
    """A dataset with Fletcher-32 per chunk (an empty one, which cannot be chunked, is covered by
    its seal instead). Chunked, in a file without a chunk cache, its data is written by this call:
    a full disk raises here, never later when the handle is freed (a small contiguous dataset waits
    in HDF5's sieve buffer until then, where the error is only printed)."""
    if data.size == 0:
        return group.create_dataset(name, data=data)
    return group.create_dataset(name, data=data, chunks=options.pop("chunks", True), fletcher32=True, **options)


def read_series(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as h5:
        required = stored_seal(h5) is not None
        check_seal(h5["series"], required)
        out = {}
        for name, ds in h5["series"].items():
            check_seal(ds, required)
            out[name] = read(ds)
        return out


def run_status(h5_path: Path) -> str | None:
    """The ``status`` attribute of a run file ('running', 'finished', 'interrupted', ...), its
    root seal checked; None when the file is missing or cannot be opened as HDF5 (a start cut
    short). :class:`DamagedFileError` when the root attributes do not match their seal."""
    try:
        h5 = h5py.File(h5_path, "r")
    except OSError:
        return None
    with h5:
        check_seal(h5, stored_seal(h5) is not None)
        return str(attr_value(h5.attrs, "status", ""))


_NAN = float("nan")


@dataclass(frozen=True)
class RunInfo:
    """What one run file says about itself (dimensionless units).

    k: spring constant per length; V_s: loading velocity; sigma: normal stress;
    m_b: top-wall mass per length; slip_rule: the run's slip rule (its stored slips section at V_s).
    Forks also carry branch ('drained' or 'perm_K'), parent_run and fork_slip.
    """

    run_dir: Path
    h5_path: Path
    config: dict
    status: str
    dt: float
    k: float
    V_s: float
    sigma: float
    m_b: float
    width: float
    n_grains: int
    load_start_time: float
    has_fluid: bool
    permeability: float | None
    n_samples: int
    series_names: tuple
    branch: str | None = None
    parent_run: str | None = None
    fork_slip: int | None = None

    @property
    def filter_width(self) -> float | None:
        """fluid.filter_width [d] of a wet run (the coupling's averaging width); None dry. A run
        written before the key existed had no filter: 0."""
        fluid = self.config.get("fluid")
        return float(fluid.get("filter_width", 0.0)) if fluid else None

    @property
    def grid_spacing(self) -> float | None:
        """The pressure grid's spacing h [d] of a wet run (fluid.cell_size, default half the filter
        width); None dry."""
        fluid = self.config.get("fluid")
        if not fluid:
            return None
        h = fluid.get("cell_size")
        return float(h) if h is not None else 0.5 * float(fluid.get("filter_width", 0.0))

    @property
    def slip_rule(self) -> SlipRule:
        """The run's slip rule, from its stored config (keys an older file lacks: the defaults)."""
        return SlipRule.from_stored(self.config.get("slips") or {}, self.V_s)

    @property
    def predicted_half_period(self) -> float:
        """Block-slider slip duration pi sqrt(m_b / k) (thesis Eq. 3) [t0]."""
        return half_period(self.m_b, self.k)

    @property
    def is_fork(self) -> bool:
        return self.branch is not None

    @property
    def parent_dir(self) -> Path | None:
        """A fork's parent run directory: parent_run is stored relative to the branch folder, so it
        is joined to run_dir (never to the current directory); None for a run that is no fork."""
        if not self.is_fork:
            return None
        if not self.parent_run:
            return Path(os.path.normpath(self.run_dir.absolute() / ".." / ".." / ".."))
        return Path(os.path.normpath(self.run_dir.absolute() / self.parent_run))

    def describe(self) -> str:
        if self.is_fork:
            return f"fork {self.run_dir} (branch {self.branch} of slip {self.fork_slip})"
        return f"run {self.run_dir}"



def _locate(path: Path) -> tuple[Path, Path]:
    path = Path(path)
    if path.is_file():
        return path.parent, path
    if not path.exists():
        raise NotARunError(f"{path} does not exist")
    h5_path = RunLayout(path).run_file
    if not h5_path.is_file():
        raise NotARunError(f"{path} is not a gouge run directory (no {RUN_FILE} in it); "
                           "give the directory that `gouge run --out` or `gouge restart` wrote")
    return path, h5_path



class RunReader:
    """Open run file with sliced series access. Use as a context manager.

    ``allow_running=False`` raises :class:`RunStillRunningError` for status 'running';
    ``allow_running=True`` also opens a file its writer still holds (read without the HDF5 file
    lock: what was flushed). The root attributes and the time series are checked on opening (seal,
    chunk checksums, time increasing), every other series, snapshot and slip when it is read; a
    damaged one raises :class:`DamagedFileError` (module doc).
    """

    def __init__(self, path: Path | str, allow_running: bool = False):
        run_dir, h5_path = _locate(Path(path))
        try:
            self.h5 = _open_for_reading(h5_path, allow_running)
        except OSError as exc:
            raise NotARunError(f"{h5_path} cannot be read as HDF5 ({exc}); "
                               "if its run is still going, wait for it to finish") from exc
        try:
            self.sealed = stored_seal(self.h5) is not None
            check_seal(self.h5, self.sealed)
            self.info = self._read_info(run_dir, h5_path)
            self._checked: set = set()
            self._time = checked_time(self.h5, self.sealed)
            if self.info.status == "running" and not allow_running:
                what = self.info.describe()
                hint = ("wait for `gouge restart` to finish, or run it again with --force"
                        if self.info.is_fork else
                        "wait for it to finish, or `gouge resume` it if it was killed")
                raise RunStillRunningError(f"{what} has status 'running': {hint}")
        except STRUCTURE_ERRORS as err:         # damaged groups or links, met while opening
            damaged = structure_error(self.h5, err)
            self.h5.close()
            raise damaged from None
        except Exception:
            self.h5.close()
            raise

    def _read_info(self, run_dir: Path, h5_path: Path) -> RunInfo:
        h5 = self.h5
        if "series" not in h5 or "time" not in h5["series"] or "config" not in h5.attrs:
            raise NotARunError(f"{h5_path} is not a gouge run file (no config attribute or /series/time)")
        cfg = yaml.safe_load(attr_value(h5.attrs, "config")) or {}
        loading = cfg.get("loading") or {}
        fluid = cfg.get("fluid")
        m_b = attr_value(h5.attrs, "wall_mass_per_length")
        if m_b is None:
            m_b = loading.get("wall_mass")
        if m_b is None:
            raise NotARunError(f"{h5_path} has no wall_mass_per_length attribute")
        series = h5["series"]
        fork_slip = attr_value(h5.attrs, "fork_slip")
        return RunInfo(
            run_dir=run_dir, h5_path=h5_path, config=cfg,
            status=str(attr_value(h5.attrs, "status", "unknown")),
            dt=float(attr_value(h5.attrs, "dt", _NAN)),
            k=float(loading.get("spring_constant", _NAN)),
            V_s=float(loading.get("velocity", _NAN)),
            sigma=float(loading.get("normal_stress", _NAN)),
            m_b=float(m_b),
            width=float(attr_value(h5.attrs, "width", _NAN)),
            n_grains=int(attr_value(h5.attrs, "n_grains", 0)),
            load_start_time=float(attr_value(h5.attrs, "load_start_time", _NAN)),
            has_fluid=bool(fluid),
            permeability=float(fluid["permeability"]) if fluid and "permeability" in fluid else None,
            n_samples=int(series["time"].shape[0]),
            series_names=tuple(sorted(series.keys())),
            branch=attr_value(h5.attrs, "branch"),
            parent_run=attr_value(h5.attrs, "parent_run"),
            fork_slip=None if fork_slip is None else int(fork_slip),
        )

    def __enter__(self) -> "RunReader":
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if self.h5.id.valid:
            self.h5.close()

    # series ---------------------------------------------------------------
    def has(self, name: str) -> bool:
        return name in self.h5["series"]

    def series(self, names, start: int = 0, stop: int | None = None) -> dict[str, np.ndarray | None]:
        """Samples ``start:stop`` of each named series, shape (stop - start,); None if absent."""
        group = self.h5["series"]
        stop = self.info.n_samples if stop is None else stop
        return {n: (self._dataset(group, n)[start:stop].astype(float) if n in group else None) for n in names}

    def _dataset(self, group, name: str):
        """A series as a sliceable view whose reads are checked (its seal once, chunks on every read)."""
        ds = group[name]
        if ds.name not in self._checked:
            check_seal(ds, self.sealed)
            self._checked.add(ds.name)
        return _Checked(ds)

    def index_at_or_after(self, t: float) -> int:
        """First sample index with time >= t."""
        return int(np.searchsorted(self._time, t, side="left"))

    def index_at_or_before(self, t: float) -> int:
        """Last sample index with time <= t."""
        return int(np.searchsorted(self._time, t, side="right")) - 1

    def time_offset(self) -> float:
        """time - load_time (the absolute time at which the driver started) [t0]."""
        if self.has("load_time") and self.info.n_samples:
            return float(self._time[0] - self._dataset(self.h5["series"], "load_time")[0])
        return self.info.load_start_time if math.isfinite(self.info.load_start_time) else 0.0

    def attributes(self) -> dict:
        """Every root attribute of the file, decoded (JSON ones such as scales and provenance as text)."""
        return {k: attr_value(self.h5.attrs, k) for k in self.h5.attrs.keys()}

    def documentation(self, group: str) -> dict[str, tuple[str, str]]:
        """(unit, description) of each dataset of ``group`` ("series", "snapshots/<step>", ...)."""
        return {name: (str(attr_value(ds.attrs, "unit", "-")), str(attr_value(ds.attrs, "description", "")))
                for name, ds in self.h5[group].items() if isinstance(ds, h5py.Dataset)}

    # snapshots ------------------------------------------------------------
    def snapshot_names(self) -> list[str]:
        return sorted(self.h5["snapshots"].keys()) if "snapshots" in self.h5 else []

    def snapshot_times(self) -> list[float]:
        return [float(self._snapshot_group(n).attrs["time"]) for n in self.snapshot_names()]

    def _snapshot_group(self, name: str):
        grp = self.h5["snapshots"][name]
        if grp.name not in self._checked:
            check_seal(grp, self.sealed)
            self._checked.add(grp.name)
        return grp

    def snapshot_array(self, name: str, key: str) -> np.ndarray:
        """One dataset of snapshot `name` (e.g. 'pressure'), checked."""
        ds = self._snapshot_group(name)[key]
        check_seal(ds, self.sealed)
        return read(ds)

    def snapshot(self, name: str) -> dict:
        """One snapshot group as arrays (grains, contacts, optional pressure/porosity fields)."""
        grp = self._snapshot_group(name)
        out = {key: self.snapshot_array(name, key) for key in grp.keys()}
        out["time"] = float(grp.attrs["time"])
        out["step"] = int(grp.attrs["step"])
        if "pressure" in grp and "origin" in grp["pressure"].attrs:
            out["grid"] = {k: np.asarray(grp["pressure"].attrs[k], float) for k in ("origin", "spacing")}
        return out



class _Checked:
    """Slicing a dataset through :func:`gouge_cli.io.integrity.read`."""

    def __init__(self, ds):
        self.ds = ds

    def __getitem__(self, selection):
        return read(self.ds, selection)


def checked_time(h5, required: bool) -> np.ndarray:
    """/series/time of an open run file, checked: seal, chunk checksums, finite and never
    decreasing (DamagedFileError naming the first row that breaks it)."""
    try:
        if "series" not in h5 or "time" not in h5["series"]:
            return np.zeros(0)
        ds = h5["series"]["time"]
    except STRUCTURE_ERRORS as err:
        raise structure_error(h5, err) from None
    check_seal(h5["series"], required)
    check_seal(ds, required)
    t = read(ds)
    bad = np.flatnonzero(~np.isfinite(t) | np.concatenate([[False], np.diff(t) < 0]))
    if bad.size:
        k = int(bad[0])
        raise DamagedFileError(f"{h5.filename}:/series/time: row {k} ({t[k]:.6g}) does not follow row {k - 1} "
                               f"({t[k - 1] if k else float('nan'):.6g}): the time series is damaged"
                               + (f" ({bad.size} rows)" if bad.size > 1 else ""))
    return t


def open_run(path: Path | str, allow_running: bool = False) -> RunReader:
    """Open a run directory (or its run.h5) for reading; see :class:`RunReader`."""
    return RunReader(path, allow_running)



def _open_for_reading(h5_path: Path, unlocked: bool) -> h5py.File:
    """h5py.File read-only; when its writer holds the HDF5 lock (a run in progress) and ``unlocked``,
    opened again without taking the lock (the rows flushed so far). The first error is raised."""
    try:
        return h5py.File(h5_path, "r")
    except OSError as first:
        if not unlocked:
            raise
        try:
            return h5py.File(h5_path, "r", locking=False)
        except OSError:
            raise first from None


def read_series_items(h5_path: Path, name: str, key) -> np.ndarray:
    """``/series/<name>[key]`` of a run file, opened for this one read (read-only, a running run's
    flushed rows too); what gouge_cli.api's lazy series call."""
    with _open_for_reading(Path(h5_path), True) as h5:
        return h5["series"][name][key]


def _table_to_group(group: h5py.Group, rows: list[dict], columns) -> None:
    group.attrs["columns"] = json.dumps(list(columns))
    for col in columns:
        values = [r.get(col) for r in rows]
        if all(isinstance(v, (bool, np.bool_)) for v in values) and values:
            _checked(group, col, np.asarray(values, dtype=bool))
        elif all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
                 for v in values):
            _checked(group, col, np.asarray(values, dtype=float))
        else:       # text: chunked (written by this call) without filters, which HDF5 refuses for it
            group.create_dataset(col, data=np.asarray(["" if v is None else str(v) for v in values],
                                                      dtype=h5py.string_dtype()), chunks=True)


def analysis_bytes(tables: dict) -> int:
    """Bytes ``/analysis`` may take in run.h5, over-estimated: 40 columns of 64 bytes a row, and
    1 MB for its attributes, descriptions and seals; `tables` as in write_analysis_tables."""
    return 64 * 40 * sum(len(rows) for rows, _ in tables.values()) + 1_000_000


def write_analysis_tables(h5_path: Path, notch: bool, summary: str, tables: dict,
                          units: dict[str, dict[str, str]] | None = None) -> None:
    """Replace ``/analysis`` in run.h5 (written by `gouge analyze`): attrs created, version, notch,
    summary (JSON); one group per table, `tables` = {name: (rows as dicts, columns)}, one dataset
    per column, its unit from `units` = {name: {column: unit}} (filedoc.ANALYSIS_UNITS for a table
    not in it). Its room (analysis_bytes) is allocated first (io.outputs.preallocate): ENOSPC then,
    with nothing written. Raises OSError if the file cannot be written (read-only, or open elsewhere)."""
    preallocate(h5_path, analysis_bytes(tables))
    with h5py.File(h5_path, "a", rdcc_nbytes=0) as h5:       # (written by each call: RunFile's rule)
        if "analysis" in h5:
            del h5["analysis"]
        grp = h5.create_group("analysis")
        grp.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        grp.attrs["version"] = __version__
        grp.attrs["notch"] = notch
        grp.attrs["summary"] = summary
        for name, (rows, columns) in tables.items():
            _table_to_group(grp.create_group(name), rows, columns)
        document_analysis(grp, units or {})
        seal_tree(grp)
