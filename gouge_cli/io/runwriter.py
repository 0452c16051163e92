"""The run file's writer, :class:`RunFile`: append-only, flushed in rows, closed (and its root
attributes written) so that a kill at any moment leaves run.h5 whole (layout:
:mod:`gouge_cli.io.runfile`)."""

from __future__ import annotations

import errno
import json
import os
import shutil
import time
from pathlib import Path

import h5py
import numpy as np

from .. import __version__
from . import provenance
from ..config import Config, dump_config
from ..errors import NoSpaceError
from .filedoc import SNAPSHOT, SNAPSHOT_ATTRS, describe, describe_attributes, document_run_file, document_slip, grid_geometry
from ..kernels import layout as L
from .integrity import SEAL, checked_dataset, seal
from .outputs import free_bytes, is_no_space, preallocate, require_space, temporary
from .recovery import SeriesTail, rows_digest
from .rundir import RESERVE_BYTES
from .runfile import SERIES, SERIES_CHUNK
from .slipcatalog import SlipEntry
from ..units import pint_unit


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
        return SeriesTail(rows, {name: rows_digest(ds[start:rows]) for name, ds in group.items()} if rows > start else {})

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
            checked_dataset(grp, name, arr, compression="gzip", compression_opts=1)
        for name, arr in fields.items():
            checked_dataset(grp, name, arr).attrs.update(geometry)
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
            checked_dataset(group, key, np.array(getattr(entry, key), float))
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
