"""gouge from Python: runs, slips, snapshots, pairs, studies and campaigns as xarray and pandas
objects, and the workflows (run, restart, study) launched from a notebook.

    import gouge_cli as gouge
    run = gouge.open_run("runs/demo")
    run.series                   # xarray.Dataset, lazy; coordinates time [t0 since loading] and time_s [s]
    run.slips                    # pandas.DataFrame, one row per slip (catalog, Eq. 3 fit, m_eff, checkpoint)
    run.snapshot(-1)             # xarray.Dataset of grains (and pore-pressure/porosity grids when wet)
    pair = run.pair(2, 1e-3)     # drained and undrained branches of slip 2 on one time axis + pair.json's measures
    gouge.open_study("runs/demo")      # pandas.DataFrame, one row per pair

Everything is read through :mod:`gouge_cli.io.runfile` (the one reader of run.h5) and computed
by the functions the CLI uses (analysis.catalog, analysis.forkpairs.classify_fork: the one pair
definition), so the numbers are those of ``gouge slips --json``, ``gouge analyze`` and pair.json.
Opening and reading never write a byte of a run (analyze, figures and the launchers write what
their commands write). A run in progress opens (its status says 'running') and shows the rows
flushed so far. Units are the dimensionless scales of the run file
(length d, stress E, time t0, velocity v0); every variable carries ``units`` and ``description``.
Errors are gouge_cli.errors exceptions with the CLI's message; ``exc.exit_code`` is the CLI's code.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
import yaml
from xarray.backends import BackendArray
from xarray.core import indexing

from .analysis.catalog import CATALOG_COLUMNS, catalog_table, fit_slip, read_catalog
from .analysis.forkpairs import PAIR_COLUMNS, classify_fork, fork_branches, fork_dirs, run_pairs
from .analysis.study import transient_slips
from .config import Config, build_config, load_config
from .errors import AnalysisError, ConfigError, SlipNotFoundError
from .io.filedoc import ANALYSIS_UNITS, SLIP_ATTRS, TIME_ORIGIN
from .io.layout import RunLayout
from .io.runfile import RunInfo, RunReader, read_series_items

__all__ = ["Run", "Fork", "Pair", "open_run", "open_study", "open_campaign", "analyze", "figures", "run", "restart",
           "study"]

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


def _attrs(unit: str, description: str) -> dict:
    return {"units": unit, "description": description}


class Run:
    """One run directory (a loading run or a fork branch), read-only. Build with :func:`open_run`.

    info: the :class:`~gouge_cli.io.runfile.RunInfo` (k, V_s, sigma, m_b, status, ...);
    time_offset: the stored clock at the loading start [t0] (every time here is since then).
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
        return self.info.run_dir

    @property
    def status(self) -> str:
        return self.info.status

    @property
    def scales(self) -> dict:
        """SI value of each unit: length_m, stress_pa, density_kg_m3, velocity_m_s, time_s."""
        return json.loads(self._attributes.get("scales") or "{}")

    @property
    def config(self) -> Config:
        """The validated config the run was made with."""
        return build_config(self.info.config)

    @property
    def provenance(self) -> dict:
        """What wrote the file (version, commit, command, libraries, CPU, threads); ``resumed``:
        the latest `gouge resume`'s, when there was one; ``final_state_hash`` when it stopped."""
        out = json.loads(self._attributes.get("provenance") or "{}")
        if self._attributes.get("provenance_resumed"):
            out["resumed"] = json.loads(self._attributes["provenance_resumed"])
        if self._attributes.get("final_state_hash"):
            out["final_state_hash"] = self._attributes["final_state_hash"]
        return out

    def __repr__(self) -> str:
        return (f"<gouge Run {self.info.describe()}: status {self.status}, {self.info.n_samples} samples, "
                f"{len(self._snapshot_names)} snapshots>")

    # time series ----------------------------------------------------------
    @property
    def series(self) -> xr.Dataset:
        """Every /series column as a lazy variable over ``time`` [t0 since loading]; coordinates
        ``time_s`` [s] and ``clock`` (the stored clock since compaction began) [t0]. Only the time
        column is read on opening; a variable is read (the slice asked for) when its values are used."""
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
            data[name] = xr.Variable(("time",), lazy, attrs=_attrs(unit, description))
        info = self.info
        attrs = {"run": str(info.run_dir), "status": info.status, "k": info.k, "V_s": info.V_s,
                 "sigma": info.sigma, "m_b": info.m_b, "permeability": info.permeability or _NAN,
                 "seed": int(self._attributes.get("seed", -1)), "time_origin": TIME_DOC,
                 "units": "dimensionless: length d, stress E, time t0, velocity v0 (SI sizes: scales)",
                 "scales": json.dumps(self.scales)}
        if info.branch is not None:
            attrs.update(branch=info.branch, fork_slip=int(info.fork_slip))
        return xr.Dataset(data, coords=self._time_coords(self._clock), attrs=attrs)

    # slips ----------------------------------------------------------------
    @property
    def slips(self) -> pd.DataFrame:
        """The slip catalog, one row per slip (index: number): the columns of
        RUN/analysis/catalog.csv (onset_time, end_time since loading began, onset_clock the stored
        clock; static_strength, stress_drop [tau/sigma]; velocities over V_s; SI columns beside),
        the Eq. 3 block-slider fit (fit_amplitude, fit_half_period, fit_r2, fit_ok: it passes the
        fit bar, fit_verdict: holds / failed / inapplicable, fit_reason, m_eff = k (T_fit/pi)^2 [rho_s d^2],
        m_eff_over_m_b) and checkpoint_path (the file `gouge restart --slip N` forks from, or None).
        ``df.attrs["units"]``: the unit of each column."""
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
        df = pd.DataFrame(rows, columns=columns).set_index("number", drop=False)
        df.index.name = None
        df.attrs["units"] = {c: SLIP_UNITS.get(c, "-") for c in columns}
        return df

    # snapshots ------------------------------------------------------------
    @property
    def snapshots(self) -> "Snapshots":
        """The grain snapshots: ``len``, ``[i]`` (a Dataset, as :meth:`snapshot`), ``.times`` [t0 since loading]."""
        return Snapshots(self)

    def snapshot(self, i: int = -1) -> xr.Dataset:
        """Snapshot ``i`` (in time order; -1 the last): grains (x, z, radius, vx, vz, spin, body over
        ``grain``, the original grain number), contacts (contact_i/j, contact_fx/fz over ``contact``)
        and, for a wet run, pressure and porosity over cell centres ``x_cell``, ``z_cell`` [d]."""
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
            data[key] = xr.Variable(dims, value, attrs=_attrs(unit, description))
        if grid is not None:
            nx, nz = snap["pressure"].shape
            (x0, z0), (dx, dz) = grid["origin"], grid["spacing"]
            coords["x_cell"] = ("x_cell", x0 + (np.arange(nx) + 0.5) * dx, _attrs("d", "cell centre along the fault"))
            coords["z_cell"] = ("z_cell", z0 + (np.arange(nz) + 0.5) * dz, _attrs("d", "cell centre across the layer"))
        t = snap["time"] - self.time_offset
        attrs = {"step": snap["step"], "time": t, "time_s": t * float(self.scales.get("time_s", _NAN)),
                 "clock": snap["time"], "time_units": "t0 since loading began", "width": self.info.width}
        return xr.Dataset(data, coords=coords, attrs=attrs)

    # forks and pairs ------------------------------------------------------
    @property
    def forks(self) -> dict[int, "Fork"]:
        """The forks under RUN/forks, by slip number."""
        return {int(d.name.split("_")[-1]): Fork(d) for d in fork_dirs(self.path)}

    def fork(self, slip: int) -> "Fork":
        forks = fork_dirs(self.path)
        for d in forks:
            if int(d.name.split("_")[-1]) == int(slip):
                return Fork(d)
        listed = ", ".join(d.name.split("_")[-1].lstrip("0") for d in forks) or "none"
        raise SlipNotFoundError(f"{self.path} has no fork of slip {slip} (forked slips: {listed}); "
                                f"`gouge restart {self.path} --slip {slip} --perm K` makes one")

    def pair(self, slip: int, perm: float | None = None, main: str = "first") -> "Pair":
        """The drained/undrained pair of slip ``slip`` at permeability ``perm`` [d^2] (None: the
        only undrained branch), classified as pair.json and `gouge analyze` do."""
        return self.fork(slip).pair(perm, main)


class Snapshots:
    """The snapshots of a run, in time order (a sequence of Datasets, read when indexed)."""

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
        """(S,) snapshot times [t0 since loading]."""
        return self.run._snapshot_clock - self.run.time_offset

    @property
    def steps(self) -> list[int]:
        return [int(n) for n in self.run._snapshot_names]


class Fork:
    """RUN/forks/slip_NNN: the drained branch and the undrained ``perm_K`` branches of one slip."""

    def __init__(self, fork_dir: Path | str):
        self.path = Path(fork_dir)
        self.slip = int(self.path.name.split("_")[-1])
        drained, undrained = fork_branches(self.path)
        self._drained_dir, self._undrained_dirs = drained, undrained

    @property
    def drained(self) -> Run | None:
        return Run(self._drained_dir) if self._drained_dir is not None else None

    @property
    def undrained(self) -> dict[float, Run]:
        """Undrained branches by permeability kappa_c [d^2]."""
        runs = [Run(d) for d in self._undrained_dirs]
        return {r.info.permeability: r for r in runs}

    @property
    def pairs(self) -> pd.DataFrame:
        """One row per undrained branch: the rows of pair.json / pairs.csv (analysis.forkpairs.PAIR_COLUMNS)."""
        return _pair_frame([p.row for p in classify_fork(self.path)])

    def pair(self, perm: float | None = None, main: str = "first") -> "Pair":
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

    row: the pair.json / pairs.csv row (type, criteria, strengths, ratios, onsets [stored clock]);
    result: the :class:`~gouge_cli.analysis.pairs.PairResult` (compared slips, Eq. 3 fits).
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
        return self.row["type"]

    @property
    def branch(self) -> str:
        return self.row["branch"]

    @property
    def permeability(self) -> float:
        return float(self.row["permeability"])

    @property
    def time_offset(self) -> float:
        """The clock at the parent's loading start [t0]: times here are since then."""
        return self.drained.time_offset

    @property
    def measures(self) -> pd.Series:
        """The pair measures and type (the pair.json row) as a Series."""
        return pd.Series(self.row)

    @property
    def events(self) -> dict:
        """{"drained", "undrained"}: the compared slips (model.slip_rule.Slip, stored clock) or None."""
        return {"drained": self.result.drained_slip, "undrained": self.result.undrained_slip}

    @property
    def fits(self) -> dict:
        """{"drained", "undrained"}: Eq. 3 block-slider fits of the compared slips (BlockSliderFit or None)."""
        return {"drained": self.result.drained_fit, "undrained": self.result.undrained_fit}

    @property
    def series(self) -> xr.Dataset:
        """Both branches over one time axis [t0 since loading] (union of their samples, NaN where a
        branch has none), dimension ``branch`` = drained, undrained; units and descriptions as in
        :attr:`Run.series`. Loaded (forks are short)."""
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
        """The Eq. 3 fit V(t) = A sin(omega (t - t_0)) of a branch's compared slip over its half period
        (time since loading [t0], velocity [v0]); None when there is no fit."""
        fit = self.fits[branch]
        if fit is None or not np.isfinite(fit.omega):
            return None
        clock = np.linspace(fit.t0, fit.t0 + fit.half_period, points)
        v = fit.amplitude * np.sin(fit.omega * (clock - fit.t0))
        return xr.DataArray(v, coords={"time": ("time", clock - self.time_offset, _attrs("t0", TIME_DOC))},
                            dims="time", name=f"{branch}_fit",
                            attrs=_attrs("v0", f"Eq. 3 block-slider fit of the {branch} compared slip "
                                               f"(R^2 {fit.r2:.3g}, passes the fit bar: {fit.success})"))

    def __repr__(self) -> str:
        return f"<gouge Pair slip {self.row['slip']} drained vs {self.branch}: Type {self.type}>"


def _pair_frame(rows: list[dict], extra: tuple = ()) -> pd.DataFrame:
    df = pd.DataFrame(rows, columns=list(extra) + list(PAIR_COLUMNS))
    df.attrs["units"] = {c: ANALYSIS_UNITS.get(c, "-") for c in df.columns}
    df.attrs["units"].update(permeability="d^2", drained_onset="t0", drained_end="t0", undrained_onset="t0",
                             undrained_end="t0", k="E/d", V_s="v0", sigma="E")
    return df


def open_run(path: Path | str, allow_running: bool = True) -> Run:
    """Open a run directory (or its run.h5) read-only. ``allow_running=False`` refuses a run whose
    status is 'running', as the analysis commands do (RunStillRunningError)."""
    return Run(path, allow_running)


def open_study(path: Path | str, main: str = "first") -> pd.DataFrame:
    """Every drained/undrained pair of a study (a run directory with forks) as one DataFrame: the
    pairs.csv columns plus seed, k, sigma, V_s and transient (thesis rule, analysis.study). Forks that
    cannot be classified yet are listed in ``df.attrs["skipped"]``."""
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
    """The campaign table (what table.csv holds: ``kind`` 'run' or 'pair', the point, its swept
    values, the run statistics or the pair columns) of the finished pieces, from a campaign file
    or its output folder (which holds campaign.yaml), plus seed and permeability columns."""
    from .analysis.campaign_table import campaign_table
    from .workflows.campaign import done_points, survey
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
    points = done_points(s)
    rows, _ = campaign_table(points)
    seeds = {p.name: s.point(p.name).config.seed for p in points}
    for row in rows:
        row.setdefault("seed", seeds[row["point"]])
        row.setdefault("permeability", _NAN)
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- what the CLI writes


def _run_dir(run) -> Path:
    return run.path if isinstance(run, Run) else Path(run)


def analyze(run: Run | Path | str, notch: bool = True, main: str = "first", write: bool = True):
    """`gouge analyze` of one run: its :class:`~gouge_cli.analysis.report.RunAnalysis` (catalog,
    fits, pairs, summary); ``write``: also ``RUN/analysis/*.csv``, summary.json and /analysis in run.h5
    (the only API call besides the launchers that writes into a run)."""
    from .analysis.report import analyze_run, write_analysis

    analysis = analyze_run(_run_dir(run), notch=notch, main=main)
    if write:
        write_analysis(analysis)
    return analysis


def figures(run_dir: Run | Path | str, slip: int | None = None, out_dir: Path | str | None = None,
            notch: bool = True, main: str = "first") -> list[Path]:
    """`gouge plot`: the PNG figures of a run (and of slip ``slip`` and its fork) into ``out_dir``
    (default RUN/figures); returns the files (gouge_cli.plots.make_figures)."""
    from .plots import make_figures

    return make_figures(run_dir=_run_dir(run_dir), slip=slip, out_dir=out_dir, notch=notch, main=main)


# --------------------------------------------------------------------------- launching


def _sets(overrides) -> list[str]:
    """{"loading.velocity": 2e-5} or ["loading.velocity=2e-5"] -> --set strings (values as YAML)."""
    if not overrides:
        return []
    if isinstance(overrides, dict):
        return [f"{k}={yaml.safe_dump(v, default_flow_style=True).strip().removesuffix('...').strip()}"
                for k, v in overrides.items()]
    return list(overrides)


def run(config: Config | Path | str, out: Path | str | None = None, overrides=None, force: bool = False,
        quiet: bool = True) -> Run:
    """`gouge run`: compact, then load; returns the opened run. ``config``: a Config, a YAML path or a
    scene name; ``overrides``: {dotted key: value} (as --set). An interrupted run (Ctrl-C) comes back
    with status 'interrupted'; bad input raises the CLI's exceptions (``exc.exit_code``)."""
    from .workflows.run import default_run_dir, run_scene

    if isinstance(config, Config):
        cfg = build_config(config.to_dict(), _sets(overrides))
    else:
        cfg = load_config(config, _sets(overrides))
    target = Path(out) if out is not None else default_run_dir(cfg)
    result = run_scene(cfg, target, force=force, quiet=quiet)
    return open_run(result.out_dir)


def restart(run: Run | Path | str, slip: int, perm=(), overrides=None, duration: float | None = None,
            force: bool = False, main: str = "first", quiet: bool = True) -> Fork:
    """`gouge restart`: drained and undrained (one per ``perm`` [d^2]) branches of slip ``slip``; writes
    pair.json when ``perm`` is given; returns the opened :class:`Fork`."""
    from .workflows.fork import restart as run_restart

    run_dir = _run_dir(run)
    perms = [perm] if isinstance(perm, (int, float)) else list(perm)
    run_restart(run_dir, slip, perms, _sets(overrides), duration, force=force, main=main, quiet=quiet)
    return Fork(RunLayout(run_dir).fork(slip).root)


def study(target: Path | str, perm, slips=None, main: str = "first", jobs: int | None = None,
          out: Path | str | None = None, overrides=None, figures: bool = False, quiet: bool = True) -> pd.DataFrame:
    """`gouge study`: the loading run (a config is run first), drained + undrained forks of every
    non-transient slip (or ``slips``, e.g. [3, 4] or "3-12"), pair types and RUN/study; returns
    :func:`open_study` of the run."""
    from .workflows.study import parse_slips, run_study

    perms = [perm] if isinstance(perm, (int, float)) else list(perm)
    wanted = parse_slips(slips) if isinstance(slips, str) else (sorted(slips) if slips is not None else None)
    result = run_study(Path(target), perms, wanted, main=main, jobs=jobs,
                       out=Path(out) if out is not None else None, overrides=_sets(overrides), quiet=quiet,
                       figures=figures)
    return open_study(result.run_dir, main)
