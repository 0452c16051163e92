"""The API's read-only views of run files: :class:`Run` (one run directory), :class:`Snapshots`,
:class:`Fork` (the branches of one forked slip) and :class:`Pair` (one drained/undrained pair)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
from xarray.core import indexing

from ..analysis.catalog import CATALOG_COLUMNS, catalog_table, fit_slip, read_catalog
from ..analysis.forkpairs import classify_fork, fork_branches, fork_dirs
from ..config import Config, build_config
from ..errors import AnalysisError, SlipNotFoundError
from ..io.filedoc import TIME_ORIGIN
from ..io.layout import ForkLayout
from ..io.runreader import RunInfo, RunReader
from ..units import pint_definitions, pint_registry, pint_unit
from .frames import SLIP_UNITS, TIME_DOC, SeriesArray, pair_frame, to_si, var_attrs

_NAN = float("nan")


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
        return {"time": ("time", t, var_attrs("t0", TIME_DOC)),
                "time_s": ("time", t * float(self.scales.get("time_s", _NAN)), var_attrs("s", TIME_DOC + ", in seconds")),
                "clock": ("time", clock, var_attrs("t0", self._docs.get("time", ("t0", TIME_ORIGIN))[1]))}

    def _build_series(self) -> xr.Dataset:
        n = self._clock.size
        data = {}
        for name, (unit, description) in self._docs.items():
            if name == "time":
                continue
            lazy = indexing.LazilyIndexedArray(SeriesArray(self.info.h5_path, name, n))
            data[name] = xr.Variable(("time",), lazy, attrs=var_attrs(unit, description, name))
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
        coords["grain"] = ("grain", np.arange(n_grains), var_attrs("-", "original (packing) grain number"))
        grid = snap.get("grid")
        for key, (unit, description) in docs.items():
            value = snap[key]
            if key.startswith("contact_"):
                dims = ("contact",)
            elif value.ndim == 2:
                dims = ("x_cell", "z_cell")
            else:
                dims = ("grain",)
            data[key] = xr.Variable(dims, value, attrs=var_attrs(unit, description, key))
        if grid is not None:
            nx, nz = snap["pressure"].shape
            (x0, z0), (dx, dz) = grid["origin"], grid["spacing"]
            coords["x_cell"] = ("x_cell", x0 + (np.arange(nx) + 0.5) * dx, var_attrs("d", "cell centre along the fault"))
            coords["z_cell"] = ("z_cell", z0 + (np.arange(nz) + 0.5) * dz, var_attrs("d", "cell centre across the layer"))
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
        return {ForkLayout(d).slip: Fork(d) for d in fork_dirs(self.path)}

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
            if ForkLayout(d).slip == int(slip):
                return Fork(d)
        listed = ", ".join(str(ForkLayout(d).slip) for d in forks) or "none"
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
        self.slip = ForkLayout(self.path).slip
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
        return pair_frame([p.row for p in classify_fork(self.path)])

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
                                          var_attrs("-", f"drained: the dry twin; undrained: {self.branch}")))
            time_s = float(self.drained.scales.get("time_s", _NAN))
            ds = ds.assign_coords(time_s=("time", ds["time"].values * time_s, var_attrs("s", TIME_DOC + ", in seconds")))
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
        return xr.DataArray(v, coords={"time": ("time", clock - self.time_offset, var_attrs("t0", TIME_DOC))},
                            dims="time", name=f"{branch}_fit",
                            attrs=var_attrs("v0", f"Eq. 3 block-slider fit of the {branch} compared slip "
                                               f"(R^2 {fit.r2:.3g}, verdict: {fit.verdict})"))

    def __repr__(self) -> str:
        return f"<gouge Pair slip {self.row['slip']} drained vs {self.branch}: Type {self.type}>"
