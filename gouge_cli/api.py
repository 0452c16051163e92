"""gouge from Python: runs, slips, snapshots, pairs, studies and campaigns as xarray and pandas
objects, and the workflows (run, restart, study) launched from a notebook.

Usage::

    import gouge_cli as gouge

    run = gouge.open_run("runs/demo")  # what `make demo` wrote
    run.series                         # xarray.Dataset, lazy; time [t0 since loading], time_s [s]
    run.slips                          # pandas.DataFrame, one row per slip (catalog, Eq. 3 fit, checkpoint)
    run.snapshot(-1)                   # xarray.Dataset of grains (and pressure/porosity grids when wet)
    fork = gouge.restart(run, slip=4, perm=1e-5)   # drained + undrained branches of slip 4
    pair = run.pair(4, 1e-5)           # both branches on one time axis, with pair.json's measures
    gouge.open_study("runs/demo")      # pandas.DataFrame, one row per drained/undrained pair

Everything is read through :mod:`gouge_cli.io.runreader` (the one reader of run.h5) and computed
by the functions the CLI uses (analysis.catalog, analysis.forkpairs.classify_fork: the one pair
definition), so the numbers are those of ``gouge slips --json``, ``gouge analyze`` and pair.json.
Opening and reading never write a byte of a run (analyze, figures and the launchers write what
their commands write). A run in progress opens (its status says 'running') and shows the rows
flushed so far.

Units are the dimensionless scales of the run file (length d, written ``d_grain``; stress E,
time t0, velocity v0, density rho_s; V_s and sigma, written ``sigma_n``, the run's loading velocity
and normal stress); every variable carries ``units``, ``long_name`` and ``description``, and a
dimensionless one has ``units`` '1'. A plain pint registry refuses these names (none reads as one
of pint's own units): convert with :func:`to_si` (``run.to_si(obj)``), whose results carry SI
units, or quantify as they are with the run's registry
(``ds.pint.quantify(unit_registry=run.pint_registry())``; definitions as text:
``run.pint_definitions()``, :mod:`gouge_cli.units`). Every time is counted from the start of
loading unless its name says ``clock`` (the stored clock, which also counts the compaction).
Errors are gouge_cli.errors exceptions with the CLI's message; ``exc.exit_code`` is the CLI's code.
"""

from __future__ import annotations

import re

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
from xarray.backends import BackendArray
from xarray.core import indexing

from .analysis.catalog import CATALOG_COLUMNS, catalog_table, fit_slip, read_catalog
from .analysis.forkpairs import PAIR_COLUMNS, PAIR_UNITS, classify_fork, fork_branches, fork_dirs, run_pairs
from .analysis.study import transient_slips
from .config import Config, build_config, load_config, parse_overrides
from .errors import AnalysisError, ConfigError, RunDirError, SlipNotFoundError
from .io.filedoc import ANALYSIS_UNITS, SLIP_ATTRS, TIME_ORIGIN
from .io.layout import RunLayout
from .io.runreader import RunInfo, RunReader, read_series_items
from .units import pint_definitions, pint_registry, pint_unit, si_of, unit_sizes

__all__ = ["Run", "Fork", "Pair", "open_run", "open_study", "open_campaign", "analyze", "figures", "run", "restart",
           "study", "to_si", "Snapshots"]

_NAN = float("nan")
TIME_DOC = "time since loading began (stored clock minus the clock at the loading start)"

#: units of the slip table's columns (those not in the run file's own documentation)
SLIP_UNITS = dict(ANALYSIS_UNITS, **{k: v[0] for k, v in SLIP_ATTRS.items()},
                  peak_velocity_over_Vs="-", mean_velocity_over_Vs="-", fit_amplitude="v0", fit_half_period="t0",
                  fit_r2="-", fit_ok="-", fit_verdict="-", fit_reason="-", m_eff="rho_s d^2", m_eff_over_m_b="-",
                  checkpoint_path="-")


class _SeriesArray(BackendArray):
    """One /series column as a lazily indexed array: each read opens the file for that slice only."""

    def __init__(self, h5_path: Path, name: str, n: int):
        self.h5_path, self.name = h5_path, name
        self.shape = (n,)
        self.dtype = np.dtype("float64")

    def __getitem__(self, key):
        return indexing.explicit_indexing_adapter(key, self.shape, indexing.IndexingSupport.BASIC, self._read)

    def _read(self, key):
        return np.asarray(read_series_items(self.h5_path, self.name, key), dtype=np.float64)


def _attrs(unit: str, description: str, name: str | None = None) -> dict:
    """xarray attributes: units, a short ``long_name`` for plot labels (``name`` in words, or the
    description up to its first comma or parenthesis, at most 40 characters) and the whole sentence
    as ``description``."""
    short = name.replace("_", " ") if name else re.split(r"[,(;]", description, maxsplit=1)[0].strip()
    return {"units": pint_unit(unit), "long_name": short if len(short) <= 40 else short[:39] + "…",
            "description": description}


def to_si(obj, scales: dict, V_s: float = _NAN, sigma: float = _NAN, m_b: float = _NAN):
    """A copy of ``obj`` in SI units: an xarray DataArray or Dataset (each variable and coordinate by
    its ``units`` attribute) or a pandas DataFrame (each column by ``df.attrs["units"]``). Values in
    units made of the scales (d_grain, E, t0, v0, rho_s; V_s, sigma_n and m_b of the run) are multiplied by their
    SI size and their unit becomes the SI one ('E d^3' -> 'Pa * m**3'); the rest is left as it is.
    ``scales``: :attr:`Run.scales`. :meth:`Run.to_si` and :meth:`Pair.to_si` fill in the run's."""
    sizes = unit_sizes(scales, V_s, sigma, m_b)

    def convert(unit, kind: str):
        si = si_of(str(unit), sizes) if unit is not None and kind in "iuf" else None
        return None if si is None or si[1] == "1" else si

    if isinstance(obj, pd.DataFrame):
        out = obj.copy()
        units = dict(obj.attrs.get("units", {}))
        for column in out.columns:
            si = convert(units.get(column), out[column].dtype.kind)
            if si is not None:
                out[column] = out[column] * si[0]
                units[column] = si[1]
        out.attrs["units"] = units
        return out
    if isinstance(obj, xr.DataArray):
        name = obj.name if obj.name is not None else "_value"
        out = to_si(obj.to_dataset(name=name) if name not in obj.coords else obj.coords.to_dataset(), scales, V_s,
                    sigma, m_b)
        return out[name].rename(obj.name)
    if isinstance(obj, xr.Dataset):
        out = obj.copy()
        for name in list(out.variables):
            var = out.variables[name]
            si = convert(var.attrs.get("units"), var.dtype.kind)
            if si is None:
                continue
            new = (var.dims, var.values * si[0], dict(var.attrs, units=si[1]))
            if name in out.coords:
                out = out.assign_coords({name: new})
            else:
                out[name] = new
        return out
    raise TypeError(f"to_si takes an xarray DataArray or Dataset or a pandas DataFrame, not {type(obj).__name__}")


class Run:
    """One run directory (a loading run or a fork branch), read-only. Build with :func:`open_run`.

    Attributes:
        info: The run's ``RunInfo`` (k, V_s, sigma, m_b, status, permeability, branch, ...).
        time_offset: The stored clock at the loading start [t0]; every time here is counted from then.
        allow_running: Whether a run still running may be opened (it shows the rows flushed so far).

    Example:
        >>> import gouge_cli as gouge
        >>> run = gouge.open_run("runs/demo")
        >>> run.status
        'finished'
        >>> run.series["tau_over_sigma"].dims
        ('time',)
        >>> int(run.slips.index[0])
        1
    """

    def __init__(self, path: Path | str, allow_running: bool = True):
        self.allow_running = allow_running
        with RunReader(path, allow_running=allow_running) as r:
            self.info: RunInfo = r.info
            self.time_offset = r.time_offset()
            self._attributes = r.attributes()
            self._docs = r.documentation("series")
            self._clock = r.series(["time"])["time"]
            self._snapshot_names = r.snapshot_names()
            self._snapshot_clock = np.asarray(r.snapshot_times(), float)
        self._series = None
        self._slips = None

    # what the run is ------------------------------------------------------
    @property
    def path(self) -> Path:
        """The run directory."""
        return self.info.run_dir

    @property
    def status(self) -> str:
        """How the run stands, as stored in its file ('finished', 'running', 'interrupted', ...)."""
        return self.info.status

    @property
    def scales(self) -> dict:
        """The SI value of each unit (length_m, stress_pa, density_kg_m3, velocity_m_s, time_s)."""
        return json.loads(self._attributes.get("scales") or "{}")

    @property
    def config(self) -> Config:
        """The validated config the run was made with."""
        return build_config(self.info.config)

    @property
    def provenance(self) -> dict:
        """What wrote the file (version, commit, command, libraries, CPU, threads).

        Key ``resumed`` holds the latest ``gouge resume``'s record, when there was one, and
        ``final_state_hash`` the state hash when the run stopped."""
        out = json.loads(self._attributes.get("provenance") or "{}")
        if self._attributes.get("provenance_resumed"):
            out["resumed"] = json.loads(self._attributes["provenance_resumed"])
        if self._attributes.get("final_state_hash"):
            out["final_state_hash"] = self._attributes["final_state_hash"]
        return out

    def to_si(self, obj):
        """A series, snapshot or slip table of this run (or any xarray/pandas object with units) in
        SI units, by the run's scales (:func:`to_si`).

        Example:
            >>> si = run.to_si(run.slips)
            >>> si.attrs["units"]["onset_time"]
            's'
            >>> bool(abs(si["onset_time"].iloc[0] - si["onset_time_s"].iloc[0]) <= 1e-9 * abs(si["onset_time_s"].iloc[0]))
            True
            >>> run.to_si(run.series["time"]).attrs["units"]
            's'
        """
        return to_si(obj, self.scales, float(self.info.V_s), float(self.info.sigma), float(self.info.m_b))

    def pint_definitions(self) -> str:
        """pint definitions of this run's unit symbols (d_grain, E, t0, ..., V_s, sigma_n, m_b; :mod:`gouge_cli.units`).

        Example:
            >>> print(run.pint_definitions().splitlines()[1])
            d_grain = 0.0005 * m  # mean grain diameter d
        """
        return pint_definitions(self.scales, float(self.info.V_s), float(self.info.sigma), float(self.info.m_b))

    def pint_registry(self):
        """A pint.UnitRegistry reading every ``units`` attribute of this run (needs pint: ``pip install pint``)."""
        return pint_registry(self.scales, float(self.info.V_s), float(self.info.sigma), float(self.info.m_b))

    def __repr__(self) -> str:
        return (f"<gouge Run {self.info.describe()}: status {self.status}, {self.info.n_samples} samples, "
                f"{len(self._snapshot_names)} snapshots>")

    # time series ----------------------------------------------------------
    @property
    def series(self) -> xr.Dataset:
        """Every /series column as a lazy variable over ``time`` [t0 since loading].

        Coordinates ``time_s`` [s] and ``clock`` (the stored clock since compaction began) [t0].
        Only the time column is read on opening; a variable is read (the slice asked for) when its
        values are used.

        Example:
            >>> ds = run.series
            >>> ds["tau_over_sigma"].attrs["description"]
            'spring shear stress k (V_s t + s0 - x) / normal stress'
            >>> abs(float(ds["time"][0])) < 1e-6        # the first sample is the loading start
            True
            >>> ds["time"].attrs["units"], ds["time_s"].attrs["units"]
            ('t0', 's')
        """
        if self._series is None:
            self._series = self._build_series()
        return self._series

    def _time_coords(self, clock: np.ndarray) -> dict:
        t = clock - self.time_offset
        return {"time": ("time", t, _attrs("t0", TIME_DOC)),
                "time_s": ("time", t * float(self.scales.get("time_s", _NAN)), _attrs("s", TIME_DOC + ", in seconds")),
                "clock": ("time", clock, _attrs("t0", self._docs.get("time", ("t0", TIME_ORIGIN))[1]))}

    def _build_series(self) -> xr.Dataset:
        n = self._clock.size
        data = {}
        for name, (unit, description) in self._docs.items():
            if name == "time":
                continue
            lazy = indexing.LazilyIndexedArray(_SeriesArray(self.info.h5_path, name, n))
            data[name] = xr.Variable(("time",), lazy, attrs=_attrs(unit, description, name))
        info = self.info
        attrs = {"run": str(info.run_dir), "status": info.status, "k": info.k, "V_s": info.V_s,
                 "sigma": info.sigma, "m_b": info.m_b, "permeability": info.permeability or _NAN,
                 "seed": int(self._attributes.get("seed", -1)), "time_origin": TIME_DOC,
                 "unit_system": "dimensionless: length d, stress E, time t0, velocity v0 (SI sizes: scales, to_si)",
                 "scales": dict(self.scales)}
        if info.branch is not None:
            attrs.update(branch=info.branch, fork_slip=int(info.fork_slip))
        return xr.Dataset(data, coords=self._time_coords(self._clock), attrs=attrs)

    # slips ----------------------------------------------------------------
    @property
    def slips(self) -> pd.DataFrame:
        """The slip catalog as a DataFrame, one row per slip, indexed by the slip number.

        Columns are those of RUN/analysis/catalog.csv (onset_time and end_time since loading
        began, onset_clock on the stored clock [t0]; static_strength and stress_drop [tau/sigma];
        velocities over V_s; SI columns beside), the Eq. 3 block-slider fit (fit_amplitude,
        fit_half_period, fit_r2, fit_ok (it passes the fit bar), fit_verdict (holds, failed or
        inapplicable), fit_reason, m_eff = k (T_fit/pi)^2 [rho_s d^2], m_eff_over_m_b) and
        checkpoint_path (the file ``gouge restart --slip N`` forks from, or None).
        ``df.attrs["units"]`` holds the unit of each column.

        Example:
            >>> slips = run.slips
            >>> slips.attrs["units"]["onset_time"]
            't0'
            >>> bool((slips["stress_drop"] > 0).all())
            True
        """
        if self._slips is None:
            self._slips = self._build_slips()
        return self._slips.copy()

    def _build_slips(self) -> pd.DataFrame:
        with RunReader(self.path, allow_running=self.allow_running) as r:
            catalog = read_catalog(r)
            rows = catalog_table(r, catalog)
            fits = [fit_slip(r, entry) for entry in catalog]
        for row, fit in zip(rows, fits):
            row.update(fit_amplitude=fit.amplitude, fit_half_period=fit.half_period, fit_r2=fit.r2,
                       fit_ok=bool(fit.success), fit_verdict=fit.verdict, fit_reason=fit.verdict_reason,
                       m_eff=fit.m_eff, m_eff_over_m_b=fit.m_eff / self.info.m_b,
                       checkpoint_path=str(self.path / row["checkpoint"]) if row["checkpoint"] else None)
        columns = list(CATALOG_COLUMNS) + ["fit_amplitude", "fit_half_period", "fit_r2", "fit_ok", "fit_verdict",
                                           "fit_reason", "m_eff", "m_eff_over_m_b", "checkpoint_path"]
        df = pd.DataFrame(rows, columns=columns).set_index("number")
        df.attrs["units"] = {c: pint_unit(SLIP_UNITS.get(c, "-")) for c in df.columns}
        return df

    # snapshots ------------------------------------------------------------
    @property
    def snapshots(self) -> "Snapshots":
        """The grain snapshots, a sequence of Datasets read when indexed (see :class:`Snapshots`).

        Example:
            >>> len(run.snapshots) == len(run.snapshots.times)
            True
        """
        return Snapshots(self)

    def snapshot(self, i: int = -1) -> xr.Dataset:
        """Snapshot ``i`` in time order (-1 the last) as a Dataset.

        It holds the grains (x, z, radius, vx, vz, spin, body over ``grain``, the original grain
        number), the contacts (contact_i/j, contact_fx/fz over ``contact``) and, for a wet run, the
        pressure and porosity over cell centres ``x_cell``, ``z_cell`` [d].

        Raises:
            ~gouge_cli.errors.AnalysisError: The run has no snapshot ``i``.

        Example:
            >>> snap = run.snapshot(-1)
            >>> snap["x"].dims, snap["x"].attrs["units"]
            (('grain',), 'd_grain')
        """
        if not self._snapshot_names:
            raise AnalysisError(f"{self.info.describe()} has no snapshots (output.snapshot_interval)")
        try:
            name = self._snapshot_names[i]
        except IndexError:
            raise AnalysisError(f"{self.info.describe()} has {len(self._snapshot_names)} snapshots; "
                                f"no snapshot {i}") from None
        with RunReader(self.path, allow_running=self.allow_running) as r:
            snap = r.snapshot(name)
            docs = r.documentation(f"snapshots/{name}")
        data, coords = {}, {}
        n_grains = snap["x"].shape[0]
        coords["grain"] = ("grain", np.arange(n_grains), _attrs("-", "original (packing) grain number"))
        grid = snap.get("grid")
        for key, (unit, description) in docs.items():
            value = snap[key]
            if key.startswith("contact_"):
                dims = ("contact",)
            elif value.ndim == 2:
                dims = ("x_cell", "z_cell")
            else:
                dims = ("grain",)
            data[key] = xr.Variable(dims, value, attrs=_attrs(unit, description, key))
        if grid is not None:
            nx, nz = snap["pressure"].shape
            (x0, z0), (dx, dz) = grid["origin"], grid["spacing"]
            coords["x_cell"] = ("x_cell", x0 + (np.arange(nx) + 0.5) * dx, _attrs("d", "cell centre along the fault"))
            coords["z_cell"] = ("z_cell", z0 + (np.arange(nz) + 0.5) * dz, _attrs("d", "cell centre across the layer"))
        t = snap["time"] - self.time_offset
        attrs = {"step": snap["step"], "time": t, "time_s": t * float(self.scales.get("time_s", _NAN)),
                 "clock": snap["time"], "time_units": "t0 since loading began (clock: the stored clock [t0])",
                 "width": self.info.width}
        return xr.Dataset(data, coords=coords, attrs=attrs)

    # forks and pairs ------------------------------------------------------
    @property
    def forks(self) -> dict[int, "Fork"]:
        """The forks under RUN/forks, by slip number.

        Example:
            >>> slip = min(run.forks)
            >>> run.forks[slip].slip == slip
            True
        """
        return {int(d.name.split("_")[-1]): Fork(d) for d in fork_dirs(self.path)}

    def fork(self, slip: int) -> "Fork":
        """The fork of slip ``slip`` (RUN/forks/slip_NNN, made by :func:`restart`).

        Raises:
            ~gouge_cli.errors.SlipNotFoundError: The slip has not been forked (the message lists the forked slips).

        Example:
            >>> run.fork(slip)
            <gouge Fork of slip ...: drained, perm_...>
        """
        forks = fork_dirs(self.path)
        for d in forks:
            if int(d.name.split("_")[-1]) == int(slip):
                return Fork(d)
        listed = ", ".join(d.name.split("_")[-1].lstrip("0") for d in forks) or "none"
        raise SlipNotFoundError(f"{self.path} has no fork of slip {slip} (forked slips: {listed}); "
                                f"`gouge restart {self.path} --slip {slip} --perm K` makes one")

    def pair(self, slip: int, perm: float | None = None, main: str = "first") -> "Pair":
        """The drained/undrained pair of slip ``slip`` at permeability ``perm`` [d^2].

        ``perm`` None takes the only undrained branch; ``main`` picks the compared event of each
        branch ('first', the forked slip, or 'largest'). The pair is classified as pair.json and
        ``gouge analyze`` do.

        Example:
            >>> pair = run.pair(slip)
            >>> pair.branch.startswith("perm_")
            True
        """
        return self.fork(slip).pair(perm, main)


class Snapshots:
    """The snapshots of a run in time order, a sequence of Datasets read when indexed.

    ``len(snaps)``, ``snaps[i]`` (as :meth:`Run.snapshot`) and iteration work as for a list.

    Example:
        >>> snaps = run.snapshots
        >>> snaps[-1].attrs["step"] == snaps.steps[-1]
        True
    """

    def __init__(self, run: Run):
        self.run = run

    def __len__(self) -> int:
        return len(self.run._snapshot_names)

    def __getitem__(self, i: int) -> xr.Dataset:
        return self.run.snapshot(i)

    def __iter__(self):
        return (self.run.snapshot(i) for i in range(len(self)))

    @property
    def times(self) -> np.ndarray:
        """The snapshot times [t0 since loading], shape (S,)."""
        return self.run._snapshot_clock - self.run.time_offset

    @property
    def steps(self) -> list[int]:
        """The step number of each snapshot."""
        return [int(n) for n in self.run._snapshot_names]


class Fork:
    """The branches of one forked slip (RUN/forks/slip_NNN), drained and undrained ``perm_K``.

    Attributes:
        path: The fork directory.
        slip: The forked slip's number.

    Example:
        >>> fork = run.fork(slip)
        >>> fork.drained.info.branch, sorted(fork.undrained) == sorted(fork.pairs["permeability"])
        ('drained', True)
    """

    def __init__(self, fork_dir: Path | str):
        self.path = Path(fork_dir)
        self.slip = int(self.path.name.split("_")[-1])
        drained, undrained = fork_branches(self.path)
        self._drained_dir, self._undrained_dirs = drained, undrained

    @property
    def drained(self) -> Run | None:
        """The drained branch (the dry twin), or None when it has not been run."""
        return Run(self._drained_dir) if self._drained_dir is not None else None

    @property
    def undrained(self) -> dict[float, Run]:
        """The undrained branches by permeability kappa_c [d^2]."""
        runs = [Run(d) for d in self._undrained_dirs]
        return {r.info.permeability: r for r in runs}

    @property
    def pairs(self) -> pd.DataFrame:
        """One row per undrained branch, the rows of pair.json and pairs.csv (PAIR_COLUMNS)."""
        return _pair_frame([p.row for p in classify_fork(self.path)])

    def pair(self, perm: float | None = None, main: str = "first") -> "Pair":
        """The pair of the drained branch and the undrained branch at ``perm`` [d^2].

        ``perm`` None takes the only undrained branch; ``main`` as in :meth:`Run.pair`.

        Raises:
            ~gouge_cli.errors.AnalysisError: No undrained branch at ``perm`` (the message lists them).

        Example:
            >>> fork.pair().permeability == min(fork.undrained)
            True
        """
        pairs = classify_fork(self.path, main)
        if perm is None and len(pairs) == 1:
            return Pair(pairs[0])
        for p in pairs:
            if perm is not None and math.isclose(float(p.row["permeability"]), float(perm), rel_tol=1e-9):
                return Pair(p)
        listed = ", ".join(f"{float(p.row['permeability']):g}" for p in pairs) or "none"
        raise AnalysisError(f"{self.path} has no undrained branch with kappa_c = {perm} (branches: {listed}); "
                            f"give perm=")

    def __repr__(self) -> str:
        names = ["drained"] * (self._drained_dir is not None) + [d.name for d in self._undrained_dirs]
        return f"<gouge Fork of slip {self.slip}: {', '.join(names)}>"


class Pair:
    """One drained/undrained pair, classified by the one pair definition (analysis.pairs).

    Attributes:
        row: The record as pair.json / pairs.csv store it (type, criteria, strengths, ratios; onsets
            since loading [t0]).
        result: The ``PairResult`` of the pair definition (compared slips, Eq. 3 fits).
        drained: The drained branch, a :class:`Run`.
        undrained: The undrained branch, a :class:`Run`.

    Example:
        >>> pair = run.pair(slip)
        >>> pair.series["wall_vx"].dims
        ('branch', 'time')
        >>> [str(b) for b in pair.series["branch"].values]
        ['drained', 'undrained']
    """

    def __init__(self, fork_pair):
        self._fork_pair = fork_pair
        self.row: dict = dict(fork_pair.row)
        self.result = fork_pair.result
        self.drained = Run(fork_pair.drained_dir)
        self.undrained = Run(fork_pair.undrained_dir)
        self._series = None

    @property
    def type(self) -> str:
        """The pair type, I, II or tie, with -C when the undrained slip is complex (:doc:`/physics/pairs`)."""
        return self.row["type"]

    @property
    def branch(self) -> str:
        """The undrained branch's name (``perm_K``)."""
        return self.row["branch"]

    @property
    def permeability(self) -> float:
        """The undrained branch's permeability prefactor kappa_c [d^2]."""
        return float(self.row["permeability"])

    @property
    def time_offset(self) -> float:
        """The stored clock at the parent's loading start [t0]; times here are counted from then."""
        return self.drained.time_offset

    @property
    def measures(self) -> pd.Series:
        """The pair measures and type (the pair.json row) as a Series; onsets since loading [t0]."""
        return pd.Series(self.row)

    def to_si(self, obj):
        """:meth:`Run.to_si` with the drained branch's scales (both branches share them)."""
        return self.drained.to_si(obj)

    @property
    def events(self) -> dict:
        """The compared slip of each branch (keys drained, undrained; a pandas Series or None).

        Times are since loading began [t0] (onset_time, end_time, peak_time), as in
        :attr:`Run.slips`; the same on the stored clock are onset_clock, end_clock, peak_clock.
        ``.attrs["units"]`` holds the unit of each field.

        Example:
            >>> event = pair.events["drained"]
            >>> bool(abs(event.onset_clock - event.onset_time - pair.time_offset) < 1e-6)
            True
        """
        return {"drained": self._event(self.result.drained_slip), "undrained": self._event(self.result.undrained_slip)}

    def _event(self, slip) -> pd.Series | None:
        if slip is None:
            return None
        fields = {k: v for k, v in slip.to_dict().items() if k != "subevents"}
        fields["n_subevents"] = len(slip.subevents)
        for key in ("onset_time", "end_time", "peak_time"):
            fields[key.replace("_time", "_clock")] = fields[key]
            fields[key] = fields[key] - self.time_offset
        event = pd.Series(fields, name=self.branch)
        event.attrs["units"] = {k: pint_unit(SLIP_UNITS.get(k, "-")) for k in fields}
        return event

    @property
    def fits(self) -> dict:
        """The Eq. 3 block-slider fit of each branch's compared slip (keys drained, undrained; or None)."""
        return {"drained": self.result.drained_fit, "undrained": self.result.undrained_fit}

    @property
    def series(self) -> xr.Dataset:
        """Both branches over one time axis [t0 since loading], with dimension ``branch``.

        The time axis is the union of the branches' samples (NaN where a branch has none);
        ``branch`` is drained, undrained; units and descriptions as in :attr:`Run.series`. Loaded
        into memory (forks are short)."""
        if self._series is None:
            parts = [self.drained.series.reset_coords(drop=True).load(),
                     self.undrained.series.reset_coords(drop=True).load()]
            names = list(dict.fromkeys(n for p in parts for n in p.data_vars))
            for i, p in enumerate(parts):
                other = parts[1 - i]
                for name in names:
                    if name not in p:
                        p[name] = xr.full_like(p["wall_vx"], np.nan).assign_attrs(other[name].attrs)
            ds = xr.concat(parts, dim="branch", join="outer", combine_attrs="drop_conflicts")
            ds = ds.assign_coords(branch=("branch", np.array(["drained", "undrained"]),
                                          _attrs("-", f"drained: the dry twin; undrained: {self.branch}")))
            time_s = float(self.drained.scales.get("time_s", _NAN))
            ds = ds.assign_coords(time_s=("time", ds["time"].values * time_s, _attrs("s", TIME_DOC + ", in seconds")))
            ds.attrs.update(slip=int(self.row["slip"]), undrained_branch=self.branch,
                            permeability=self.permeability, type=self.type)
            self._series = ds
        return self._series

    def fit_curve(self, branch: str = "drained", points: int = 200) -> xr.DataArray | None:
        """The Eq. 3 fit V(t) = A sin(omega (t - t_0)) of a branch's compared slip over its half period.

        Time since loading [t0], velocity [v0]; None when there is no fit. A curve is returned
        whatever the fit's verdict (its ``description`` says it); the figures draw only fits whose
        ``pair.fits[branch].verdict`` is "holds" (docs/physics/block_slider.md).

        Example:
            >>> curve = pair.fit_curve("drained")
            >>> curve is None or curve.attrs["units"] == "v0"
            True
        """
        fit = self.fits[branch]
        if fit is None or not np.isfinite(fit.omega):
            return None
        clock = np.linspace(fit.t0, fit.t0 + fit.half_period, points)
        v = fit.amplitude * np.sin(fit.omega * (clock - fit.t0))
        return xr.DataArray(v, coords={"time": ("time", clock - self.time_offset, _attrs("t0", TIME_DOC))},
                            dims="time", name=f"{branch}_fit",
                            attrs=_attrs("v0", f"Eq. 3 block-slider fit of the {branch} compared slip "
                                               f"(R^2 {fit.r2:.3g}, verdict: {fit.verdict})"))

    def __repr__(self) -> str:
        return f"<gouge Pair slip {self.row['slip']} drained vs {self.branch}: Type {self.type}>"


def _pair_frame(rows: list[dict], extra: tuple = ()) -> pd.DataFrame:
    df = pd.DataFrame(rows, columns=list(extra) + list(PAIR_COLUMNS))
    df.attrs["units"] = {c: pint_unit(PAIR_UNITS.get(c, "-")) for c in df.columns}
    df.attrs["units"].update({c: pint_unit(u) for c, u in dict(k="E/d", V_s="v0", sigma="E").items()})
    return df


def open_run(path: Path | str, allow_running: bool = True) -> Run:
    """Open a run directory (or its run.h5) read-only.

    Args:
        path: The run directory (a loading run or a fork branch) or its run.h5.
        allow_running: False refuses a run whose status is 'running', as the analysis commands do.

    Raises:
        ~gouge_cli.errors.NotARunError: ``path`` holds no run file.
        ~gouge_cli.errors.RunStillRunningError: The run is running and ``allow_running`` is False.

    Example:
        >>> import gouge_cli as gouge
        >>> gouge.open_run("runs/demo")
        <gouge Run ...: status finished, ... samples, ... snapshots>
    """
    return Run(path, allow_running)


def open_study(path: Path | str, main: str = "first") -> pd.DataFrame:
    """Every drained/undrained pair of a study (a run directory with forks) as one DataFrame.

    The columns are those of pairs.csv plus seed, k, sigma, V_s and transient (the thesis's rule).
    Forks that cannot be classified yet are listed in ``df.attrs["skipped"]``.

    Example:
        >>> pairs = gouge.open_study("runs/demo")
        >>> {"slip", "permeability", "type", "transient"} <= set(pairs.columns)
        True
    """
    parent = Run(path, allow_running=False)
    pairs, skipped = run_pairs(parent.path, main=main)
    with RunReader(parent.path) as r:
        transient = transient_slips(read_catalog(r))
    info, seed = parent.info, int(parent._attributes.get("seed", -1))
    rows = [dict(p.row, seed=seed, k=info.k, sigma=info.sigma, V_s=info.V_s,
                 transient=int(p.row["slip"]) in transient) for p in pairs]
    df = _pair_frame(rows, ("seed", "k", "sigma", "V_s", "transient"))
    df.attrs["skipped"] = skipped
    return df


def open_campaign(spec_or_folder: Path | str) -> pd.DataFrame:
    """The campaign table of the finished pieces (from their results records), from a campaign
    file or its output folder.

    The rows are those of table.csv (``kind`` 'run' or 'pair', the point, its swept values, the
    run statistics or the pair columns) plus seed and permeability columns. The output folder
    holds the campaign.yaml it was run with.

    Example:
        >>> table = gouge.open_campaign("runs/sweep.yaml")  # doctest: +SKIP
        >>> table.groupby("loading.normal_stress")["stress_drop_mean"].mean()  # doctest: +SKIP
    """
    from .workflows.campaign import backfill, survey, table_rows
    from .workflows.campaign_spec import load_spec

    path = Path(spec_or_folder)
    if path.is_dir():
        spec_path = path / "campaign.yaml"
        spec = load_spec(spec_path).model_copy(update={"out": str(path.resolve().parent)})
        if spec.name != path.resolve().name:
            raise ConfigError(f"{path}: its campaign.yaml names campaign {spec.name!r}; give the campaign file")
    else:
        spec_path, spec = path, load_spec(path)
    s = survey(spec, spec_path)
    backfill(s, log=lambda m: None)        # a campaign run before results records: written from its folders
    rows = table_rows(s)
    seeds = {p.name: p.config.seed for p in s.points}
    for row in rows:
        row.setdefault("seed", seeds[row["point"]])
        row.setdefault("permeability", _NAN)
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- what the CLI writes


def _run_dir(run) -> Path:
    return run.path if isinstance(run, Run) else Path(run)


def analyze(run: Run | Path | str, notch: bool = True, main: str = "first", write: bool = True):
    """``gouge analyze`` of one run; returns its ``RunAnalysis`` (catalog, fits, pairs, summary).

    ``write`` also writes ``RUN/analysis/*.csv``, summary.json and /analysis in run.h5 (the only API
    call besides the launchers that writes into a run).

    Example:
        >>> analysis = gouge.analyze("runs/demo", write=False)
        >>> len(analysis.catalog) == len(gouge.open_run("runs/demo").slips)
        True
    """
    from .analysis.report import analyze_run, write_analysis

    analysis = analyze_run(_run_dir(run), notch=notch, main=main)
    if write:
        write_analysis(analysis)
    return analysis


def figures(run_dir: Run | Path | str, slip: int | None = None, out_dir: Path | str | None = None,
            notch: bool = True, main: str = "first") -> list[Path]:
    """``gouge plot``: the PNG figures of a run (and of slip ``slip`` and its fork); returns the files.

    ``out_dir`` defaults to RUN/figures.

    Example:
        >>> files = gouge.figures("runs/demo", out_dir="figures")
        >>> all(f.suffix == ".png" for f in files)
        True
    """
    from .plots import make_figures

    return make_figures(run_dir=_run_dir(run_dir), slip=slip, out_dir=out_dir, notch=notch, main=main)


# --------------------------------------------------------------------------- launching


def _overrides(overrides) -> dict:
    """{"loading.velocity": 2e-5} (as it is) or ["loading.velocity=2e-5"] (parsed as ``--set``) -> {dotted key: value}."""
    if not overrides:
        return {}
    return dict(overrides) if isinstance(overrides, dict) else parse_overrides(list(overrides))


def run(config: Config | Path | str, out: Path | str | None = None, overrides=None, force: bool = False,
        quiet: bool = True) -> Run:
    """``gouge run``: compact, then load; returns the opened run.

    Args:
        config: A Config, a YAML path or a scene name.
        out: The run directory (default runs/<name>).
        overrides: {dotted key: value}, as ``--set``.
        force: Replace what a previous run left in ``out``.
        quiet: No progress bar.

    An interrupted run (Ctrl-C) comes back with status 'interrupted'; bad input raises the CLI's
    exceptions (``exc.exit_code``).

    Example:
        >>> run = gouge.run("configs/tutorial.yaml", out="runs/first")  # doctest: +SKIP
        >>> run.status  # doctest: +SKIP
        'finished'
    """
    from .workflows.run import default_run_dir, run_scene

    if isinstance(config, Config):
        cfg = build_config(config.to_dict(), _overrides(overrides))
    else:
        cfg = load_config(config, _overrides(overrides))
    target = Path(out) if out is not None else default_run_dir(cfg)
    result = run_scene(cfg, target, force=force, quiet=quiet)
    return open_run(result.out_dir)


def restart(run: Run | Path | str, slip: int, perm=(), overrides=None, duration: float | None = None,
            force: bool = False, main: str = "first", quiet: bool = True) -> Fork:
    """``gouge restart``: drained and undrained branches of slip ``slip``; returns the opened :class:`Fork`.

    One undrained branch per ``perm`` [d^2]; pair.json is written when ``perm`` is given.
    ``duration`` [t0] bounds each branch (default: until its first slip ends).

    The pair's type (``fork.pair(K).type``) is I, II or tie, with -C when complex
    (docs/physics/pairs.md); which one a slip gives is the simulation's to say.

    Example:
        >>> fork = gouge.restart("runs/demo", slip=4, perm=3e-6)  # doctest: +SKIP
        >>> fork.pair(3e-6).type  # doctest: +SKIP
    """
    from .workflows.fork import ForkRequest, restart as run_restart

    run_dir = _run_dir(run)
    perms = (perm,) if isinstance(perm, (int, float)) else tuple(perm)
    try:
        run_restart(ForkRequest(run_dir, slip, perms, _overrides(overrides), duration, force=force, main=main),
                    quiet=quiet)
    except RunDirError as exc:          # the CLI's words, said in Python's
        raise RunDirError(str(exc).replace("pass --force", "pass force=True")) from None
    return Fork(RunLayout(run_dir).fork(slip).root)


def study(target: Path | str, perm, slips=None, main: str = "first", jobs: int | None = None,
          out: Path | str | None = None, overrides=None, figures: bool = False, quiet: bool = True) -> pd.DataFrame:
    """``gouge study``: drained and undrained forks of every slip; returns :func:`open_study` of the run.

    ``target`` is a run directory or a config (the loading run is run first); ``slips`` (e.g.
    [3, 4] or "3-12") replaces every non-transient slip. Writes the pair types and RUN/study.

    Example:
        >>> pairs = gouge.study("runs/first", perm=1e-5, slips="2-3")  # doctest: +SKIP
        >>> pairs.groupby("type").size()  # doctest: +SKIP
    """
    from .workflows.study import parse_slips, run_study

    perms = [perm] if isinstance(perm, (int, float)) else list(perm)
    wanted = parse_slips(slips) if isinstance(slips, str) else (sorted(slips) if slips is not None else None)
    result = run_study(Path(target), perms, wanted, main=main, jobs=jobs,
                       out=Path(out) if out is not None else None, overrides=_overrides(overrides), quiet=quiet,
                       figures=figures)
    return open_study(result.run_dir, main)
