"""The run file's reader: :class:`RunReader` (checked, sliced series; snapshots), :class:`RunInfo`
(what a run file says about itself), and the small reads beside it (run_status, read_series,
read_series_items); layout: :mod:`gouge_cli.io.runfile`."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import yaml

from ..errors import DamagedFileError, NotARunError, RunStillRunningError
from ..model.slip_rule import SlipRule
from ..model.timestep import half_period
from .integrity import STRUCTURE_ERRORS, attr_value, check_seal, read, stored_seal, structure_error
from .layout import RUN_FILE, RunLayout


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
