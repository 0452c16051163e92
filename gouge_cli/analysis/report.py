"""Reading run files and computing what `gouge analyze` reports (thesis Sections IV-V).

Reads only: ``RUN/run.h5`` (see :mod:`gouge_cli.io.runfile`) and the forks under
``RUN/forks/slip_NNN/{drained,perm_K}/run.h5``. The physics is in the pure
functions of :mod:`gouge_cli.analysis` (block-slider fit, Eq. 3; friction,
Eqs. 5-7; pair types) and :mod:`gouge_cli.driver.detector`; this module only finds the
samples they need. Series are sliced per slip window with h5py (sample indices
found by bisection on the ``time`` dataset), so a long run is never loaded whole
except for :func:`series_envelope`, which reads it in chunks.

All quantities are dimensionless (length d, stress E, time t0; physics.md section 1):
``tau/sigma`` and friction [-], velocities [v0] (also given over V_s), times [t0],
slip distances [d].

Errors are :class:`AnalysisError` (subclasses name the case); the CLI turns them
into exit code 2.
"""

from __future__ import annotations

import bisect
import csv
import json
import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import yaml

from .. import __version__
from ..errors import InputError
from ..driver.detector import WallSeries, detect_slips
from ..io.filedoc import document_analysis, json_safe
from ..model.timestep import half_period
from .blockslider import BlockSliderFit, fit_block_slider
from .friction import dynamic_friction, estimate_natural_frequency, mean_dynamic_friction
from .pairs import PairDefinition, PairResult, campaign_summary, classify_pair

__all__ = [
    "AnalysisError", "NotARunError", "RunStillRunningError", "NoSlipsError", "SlipNotFoundError",
    "RunInfo", "RunReader", "SlipFriction", "ForkPair", "RunAnalysis",
    "CATALOG_COLUMNS", "FIT_COLUMNS", "PAIR_COLUMNS", "SUMMARY_COLUMNS",
    "open_run", "read_catalog", "catalog_table", "summary_statistics", "fit_table",
    "slip_window", "slip_friction", "fit_slip", "fork_dirs", "fork_branches", "classify_fork", "run_pairs", "pair_definition",
    "analyze_run", "campaign", "write_analysis", "series_envelope", "find_slip",
]

_NAN = float("nan")


class AnalysisError(InputError):
    """A run cannot be analysed as asked; the message says why and what to do."""


class NotARunError(AnalysisError):
    """The path is not a gouge run directory (no readable run.h5 with series)."""


class RunStillRunningError(AnalysisError):
    """The run or fork file still has status 'running'."""


class NoSlipsError(AnalysisError):
    """The run has no slip events to analyse."""


class SlipNotFoundError(AnalysisError):
    """No slip with the requested number."""


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class RunInfo:
    """What one run file says about itself (dimensionless units).

    k: spring constant per length; V_s: loading velocity; sigma: normal stress;
    m_b: top-wall mass per length; slip_params: the detector thresholds of the run.
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
    slip_params: dict
    n_samples: int
    series_names: tuple
    branch: str | None = None
    parent_run: str | None = None
    fork_slip: int | None = None

    @property
    def predicted_half_period(self) -> float:
        """Block-slider slip duration pi sqrt(m_b / k) (thesis Eq. 3) [t0]."""
        return half_period(self.m_b, self.k)

    @property
    def is_fork(self) -> bool:
        return self.branch is not None

    def describe(self) -> str:
        if self.is_fork:
            return f"fork {self.run_dir} (branch {self.branch} of slip {self.fork_slip})"
        return f"run {self.run_dir}"


def _attr(attrs, key, default=None):
    if key not in attrs:
        return default
    value = attrs[key]
    if isinstance(value, bytes):
        return value.decode()
    return value.item() if hasattr(value, "item") else value


def _locate(path: Path) -> tuple[Path, Path]:
    path = Path(path)
    if path.is_file():
        return path.parent, path
    if not path.exists():
        raise NotARunError(f"{path} does not exist")
    h5_path = path / "run.h5"
    if not h5_path.is_file():
        raise NotARunError(f"{path} is not a gouge run directory (no run.h5 in it); "
                           "give the directory that `gouge run --out` or `gouge restart` wrote")
    return path, h5_path


class RunReader:
    """Open run file with sliced series access. Use as a context manager.

    ``allow_running=False`` raises :class:`RunStillRunningError` for status 'running'.
    """

    def __init__(self, path: Path | str, allow_running: bool = False):
        run_dir, h5_path = _locate(Path(path))
        try:
            self.h5 = h5py.File(h5_path, "r")
        except OSError as exc:
            raise NotARunError(f"{h5_path} cannot be read as HDF5 ({exc}); "
                               "if its run is still going, wait for it to finish") from exc
        try:
            self.info = self._read_info(run_dir, h5_path)
            if self.info.status == "running" and not allow_running:
                what = self.info.describe()
                hint = ("wait for `gouge restart` to finish, or run it again with --force"
                        if self.info.is_fork else
                        "wait for it to finish, or `gouge resume` it if it was killed")
                raise RunStillRunningError(f"{what} has status 'running': {hint}")
        except Exception:
            self.h5.close()
            raise
        self._time = self.h5["series"]["time"]

    def _read_info(self, run_dir: Path, h5_path: Path) -> RunInfo:
        h5 = self.h5
        if "series" not in h5 or "time" not in h5["series"] or "config" not in h5.attrs:
            raise NotARunError(f"{h5_path} is not a gouge run file (no config attribute or /series/time)")
        cfg = yaml.safe_load(_attr(h5.attrs, "config")) or {}
        loading = cfg.get("loading") or {}
        fluid = cfg.get("fluid")
        slips = cfg.get("slips") or {}
        m_b = _attr(h5.attrs, "wall_mass_per_length")
        if m_b is None:
            m_b = loading.get("wall_mass")
        if m_b is None:
            raise NotARunError(f"{h5_path} has no wall_mass_per_length attribute")
        series = h5["series"]
        slip_params = {
            "start_factor": float(slips.get("start_factor", 10.0)),
            "end_factor": float(slips.get("end_factor", 2.0)),
            "min_duration": float(slips.get("min_duration", 0.0)),
            "min_slip": float(slips.get("min_slip", 0.0)),
            "merge_gap": float(slips.get("merge_gap", 0.0)),
        }
        fork_slip = _attr(h5.attrs, "fork_slip")
        return RunInfo(
            run_dir=run_dir, h5_path=h5_path, config=cfg,
            status=str(_attr(h5.attrs, "status", "unknown")),
            dt=float(_attr(h5.attrs, "dt", _NAN)),
            k=float(loading.get("spring_constant", _NAN)),
            V_s=float(loading.get("velocity", _NAN)),
            sigma=float(loading.get("normal_stress", _NAN)),
            m_b=float(m_b),
            width=float(_attr(h5.attrs, "width", _NAN)),
            n_grains=int(_attr(h5.attrs, "n_grains", 0)),
            load_start_time=float(_attr(h5.attrs, "load_start_time", _NAN)),
            has_fluid=bool(fluid),
            permeability=float(fluid["permeability"]) if fluid and "permeability" in fluid else None,
            slip_params=slip_params,
            n_samples=int(series["time"].shape[0]),
            series_names=tuple(sorted(series.keys())),
            branch=_attr(h5.attrs, "branch"),
            parent_run=_attr(h5.attrs, "parent_run"),
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
        return {n: (group[n][start:stop].astype(float) if n in group else None) for n in names}

    def index_at_or_after(self, t: float) -> int:
        """First sample index with time >= t (bisection on the dataset, no full read)."""
        return bisect.bisect_left(self._time, t)

    def index_at_or_before(self, t: float) -> int:
        """Last sample index with time <= t."""
        return bisect.bisect_right(self._time, t) - 1

    def time_offset(self) -> float:
        """time - load_time (the absolute time at which the driver started) [t0]."""
        if self.has("load_time") and self.info.n_samples:
            return float(self._time[0] - self.h5["series"]["load_time"][0])
        return self.info.load_start_time if math.isfinite(self.info.load_start_time) else 0.0

    # snapshots ------------------------------------------------------------
    def snapshot_names(self) -> list[str]:
        return sorted(self.h5["snapshots"].keys()) if "snapshots" in self.h5 else []

    def snapshot_times(self) -> list[float]:
        return [float(self.h5["snapshots"][n].attrs["time"]) for n in self.snapshot_names()]

    def snapshot(self, name: str) -> dict:
        """One snapshot group as arrays (grains, contacts, optional pressure/porosity fields)."""
        grp = self.h5["snapshots"][name]
        out = {key: grp[key][...] for key in grp.keys()}
        out["time"] = float(grp.attrs["time"])
        out["step"] = int(grp.attrs["step"])
        if "pressure" in grp and "origin" in grp["pressure"].attrs:
            out["grid"] = {k: np.asarray(grp["pressure"].attrs[k], float) for k in ("origin", "spacing")}
        return out


def open_run(path: Path | str, allow_running: bool = False) -> RunReader:
    """Open a run directory (or its run.h5) for reading; see :class:`RunReader`."""
    return RunReader(path, allow_running)


# --------------------------------------------------------------------------- catalog

CATALOG_COLUMNS = (
    "number", "onset_time", "onset_since_loading", "end_time", "duration", "slip", "static_strength", "stress_drop",
    "peak_velocity", "mean_velocity", "peak_velocity_over_Vs", "mean_velocity_over_Vs",
    "recurrence", "porosity_change", "n_subevents", "deborah", "pressure_min", "pressure_max",
    "checkpoint",
)
SUMMARY_COLUMNS = (
    "duration", "slip", "static_strength", "stress_drop", "peak_velocity_over_Vs",
    "mean_velocity_over_Vs", "recurrence", "porosity_change", "deborah",
)
FIT_COLUMNS = (
    "number", "duration", "half_period", "predicted_half_period", "half_period_ratio",
    "amplitude", "amplitude_over_Vs", "delta_mu", "static_friction", "mean_dynamic_friction",
    "delta_mu_eq7", "notch_frequency", "r2", "nrms", "n_points", "success", "reason",
    "m_eff", "m_eff_over_m_b",
)
PAIR_COLUMNS = (
    "run", "slip", "branch", "permeability", "main", "type", "base_type", "complex", "criteria",
    "undrained_event", "drained_strength", "undrained_strength", "strength_difference",
    "peak_velocity_ratio", "stress_drop_ratio", "duration_ratio", "drained_peak_over_Vs",
    "undrained_peak_over_Vs", "n_undrained_slips", "n_subevents", "drained_onset", "drained_end",
    "undrained_onset", "undrained_end", "drained_fit_r2", "drained_fit_ok", "undrained_fit_r2",
    "deborah_mean", "note",
)


def _stored_catalog(reader: RunReader) -> list[dict] | None:
    h5 = reader.h5
    if "slips" not in h5:
        return None
    out = []
    for name in sorted(h5["slips"]):
        g = h5["slips"][name]
        entry = {k: _attr(g.attrs, k) for k in g.attrs.keys()}
        entry["subevent_time"] = g["subevent_time"][...].tolist() if "subevent_time" in g else []
        entry["subevent_velocity"] = g["subevent_velocity"][...].tolist() if "subevent_velocity" in g else []
        out.append(entry)
    return out


def _detected_catalog(reader: RunReader) -> list[dict]:
    s = reader.series(["time", "wall_x", "wall_vx", "tau_over_sigma", "porosity"])
    if s["wall_vx"] is None:
        raise NotARunError(f"{reader.info.h5_path} has no /series/wall_vx")
    slips = detect_slips(s["time"], s["wall_vx"], reader.info.V_s, x_wall=s["wall_x"],
                         tau_over_sigma=s["tau_over_sigma"], porosity=s["porosity"],
                         **reader.info.slip_params)
    out = []
    for number, slip in enumerate(slips, start=1):
        entry = slip.to_dict()
        subs = entry.pop("subevents")
        entry.update(number=number, checkpoint="",
                     subevent_time=[e["time"] for e in subs],
                     subevent_velocity=[e["velocity"] for e in subs])
        out.append(entry)
    return out


def read_catalog(reader: RunReader, detect: bool = False) -> list[dict]:
    """The run's slips as dicts (the /slips catalog written while it ran).

    Runs without a /slips group (or ``detect=True``) are scanned with
    :func:`~gouge_cli.driver.detector.detect_slips` using the run's own thresholds.
    """
    catalog = None if detect else _stored_catalog(reader)
    return _detected_catalog(reader) if catalog is None else catalog


def slip_window(reader: RunReader, entry: dict, pad: float = 0.0) -> tuple[int, int, int, int]:
    """Sample indices of one slip: ``(i0, i1, j0, j1)``.

    ``i0``: first sample at or after the onset; ``i1``: last sample at or before the end
    (the detector's onset and end samples); ``[j0, j1)``: the slice to read, widened
    by ``pad`` slip durations on each side.
    """
    t_on, t_end = float(entry["onset_time"]), float(entry["end_time"])
    i0 = reader.index_at_or_after(t_on)
    i1 = max(reader.index_at_or_before(t_end), i0)
    width = pad * (t_end - t_on)
    j0 = max(reader.index_at_or_before(t_on - width), 0) if pad > 0 else i0
    j1 = min(reader.index_at_or_after(t_end + width) + 1, reader.info.n_samples) if pad > 0 else i1 + 1
    j1 = max(j1, min(i1 + 2, reader.info.n_samples))
    return i0, i1, min(j0, i0), j1


def find_slip(catalog: list[dict], number: int) -> dict:
    for entry in catalog:
        if int(entry["number"]) == number:
            return entry
    listed = ", ".join(str(int(e["number"])) for e in catalog) or "none"
    raise SlipNotFoundError(f"no slip number {number}; the run has slips {listed}")


def _nan_mean(a) -> float:
    if a is None:
        return _NAN
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else _NAN


def _nan_ext(a, fn) -> float:
    if a is None:
        return _NAN
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(fn(a)) if a.size else _NAN


def catalog_table(reader: RunReader, catalog: list[dict] | None = None) -> list[dict]:
    """One row per slip with :data:`CATALOG_COLUMNS`.

    onset_time: the stored clock (since compaction began); onset_since_loading: the same
    onset in t0 since loading began (the time origin of every command and figure);
    static_strength: tau/sigma before the onset; stress_drop: drop of tau/sigma;
    velocities [v0] and over V_s; recurrence: onset minus the previous onset [t0]
    (NaN for the first); deborah: mean of the Deborah-number series over the slip
    samples (NaN for a dry run); pressure_min/max: extremes of the pore-pressure
    series over the slip [E].
    """
    if catalog is None:
        catalog = read_catalog(reader)
    V_s = reader.info.V_s
    fluid_names = ("deborah", "pressure_min", "pressure_max")
    has_fluid_series = any(reader.has(n) for n in fluid_names)
    rows, previous = [], None
    origin = reader.time_offset()
    for entry in catalog:
        onset = float(entry["onset_time"])
        deborah = p_min = p_max = _NAN
        if has_fluid_series:
            i0, i1, _, _ = slip_window(reader, entry)
            s = reader.series(fluid_names, i0, i1 + 1)
            deborah = _nan_mean(s["deborah"])
            p_min = _nan_ext(s["pressure_min"], np.min)
            p_max = _nan_ext(s["pressure_max"], np.max)
        peak, mean = float(entry["peak_velocity"]), float(entry["mean_velocity"])
        rows.append({
            "number": int(entry["number"]),
            "onset_time": onset,
            "onset_since_loading": onset - origin,
            "end_time": float(entry["end_time"]),
            "duration": float(entry["duration"]),
            "slip": float(entry["slip"]),
            "static_strength": float(entry["static_strength"]),
            "stress_drop": float(entry["stress_drop"]),
            "peak_velocity": peak,
            "mean_velocity": mean,
            "peak_velocity_over_Vs": peak / V_s,
            "mean_velocity_over_Vs": mean / V_s,
            "recurrence": onset - previous if previous is not None else _NAN,
            "porosity_change": float(entry.get("porosity_change", _NAN)),
            "n_subevents": len(entry.get("subevent_time", [])),
            "deborah": deborah,
            "pressure_min": p_min,
            "pressure_max": p_max,
            "checkpoint": str(entry.get("checkpoint", "") or ""),
        })
        previous = onset
    return rows


def summary_statistics(rows: list[dict], columns=SUMMARY_COLUMNS) -> dict[str, dict]:
    """Mean, standard deviation (population), min, max and count of the finite values per column."""
    out = {}
    for col in columns:
        a = np.asarray([r[col] for r in rows if col in r], dtype=float)
        a = a[np.isfinite(a)]
        out[col] = {"n": int(a.size),
                    "mean": float(a.mean()) if a.size else _NAN,
                    "std": float(a.std()) if a.size else _NAN,
                    "min": float(a.min()) if a.size else _NAN,
                    "max": float(a.max()) if a.size else _NAN}
    return out


# --------------------------------------------------------------------------- fits and friction


def _uniform(t: np.ndarray, *ys: np.ndarray):
    """Resample onto a uniform cadence when the samples are not uniform (notch filter needs it)."""
    dt = np.diff(t)
    if dt.size and np.ptp(dt) <= 1e-6 * dt.mean():
        return (t, *ys)
    tu = np.linspace(t[0], t[-1], t.size)
    return (tu, *(np.interp(tu, t, y) for y in ys))


@dataclass
class SlipFriction:
    """mu_d(t) (Eq. 7, drained) or R/sigma = mu_d (1 - P*/sigma) (Eq. 6, undrained) over one slip.

    Arrays of shape (n,): t [t0], v_wall [v0], tau_over_sigma, friction (R/sigma
    unfiltered), filtered (notch-filtered, or None). mu_s: static strength (tau/sigma
    at the peak before the onset); mean_mu_d: mean over the central half of the slip.
    """

    number: int
    t: np.ndarray
    v_wall: np.ndarray
    tau_over_sigma: np.ndarray
    friction: np.ndarray
    filtered: np.ndarray | None
    notch_frequency: float
    onset_time: float
    end_time: float
    mu_s: float
    mean_mu_d: float
    drained: bool
    note: str = ""
    pressure: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        return "μ_d (Eq. 7)" if self.drained else "R/σ = μ_d (1 − P*/σ) (Eq. 6)"


def slip_friction(reader: RunReader, entry: dict, notch: bool = True, pad: float = 0.5) -> SlipFriction:
    """Dynamic friction (drained) or combined resistance (undrained) over one slip and ``pad``
    durations either side; ``notch=True`` removes the layer's natural vibration with
    :func:`~gouge_cli.analysis.friction.notch_filter` (frequency found above 5 sqrt(k/m_b)/2 pi;
    left unfiltered with a note when no peak lies below the Nyquist frequency)."""
    info = reader.info
    i0, i1, j0, j1 = slip_window(reader, entry, pad)
    names = ["time", "wall_vx", "tau_over_sigma", "pressure_mean", "pressure_min", "pressure_max"]
    s = reader.series(names, j0, j1)
    t, v, tau = s["time"], s["wall_vx"], s["tau_over_sigma"]
    pressure = {k: s[k] for k in ("pressure_mean", "pressure_min", "pressure_max") if s[k] is not None}
    t, v, tau, *pvals = _uniform(t, v, tau, *pressure.values())
    pressure = dict(zip(pressure.keys(), pvals))
    mu = dynamic_friction(t, v, info.m_b, info.sigma, tau_over_sigma=tau)
    filtered, freq, note = None, _NAN, ""
    if notch:
        try:
            filtered = dynamic_friction(t, v, info.m_b, info.sigma, tau_over_sigma=tau, notch="auto")
            fmin = 5.0 * math.sqrt(info.k / info.m_b) / (2.0 * math.pi)
            freq = estimate_natural_frequency(t, mu, f_min=fmin)
        except ValueError as exc:
            filtered, note = None, f"notch filter skipped: {exc}"
    span = (float(entry["onset_time"]), float(entry["end_time"]))
    mean_mu_d = mean_dynamic_friction(t, filtered if filtered is not None else mu, span)
    return SlipFriction(
        number=int(entry["number"]), t=t, v_wall=v, tau_over_sigma=tau, friction=mu, filtered=filtered,
        notch_frequency=freq, onset_time=span[0], end_time=span[1],
        mu_s=float(entry["static_strength"]), mean_mu_d=mean_mu_d, drained=not info.has_fluid,
        note=note, pressure=pressure)


def fit_slip(reader: RunReader, entry: dict) -> BlockSliderFit:
    """Fit thesis Eq. 3 to the wall velocity between one slip's onset and end samples."""
    info = reader.info
    i0, i1, j0, j1 = slip_window(reader, entry)
    s = reader.series(["time", "wall_vx"], j0, j1)
    window = SimpleNamespace(onset_index=i0 - j0, end_index=i1 - j0, onset_time=float(entry["onset_time"]),
                             duration=float(entry["duration"]), peak_velocity=float(entry["peak_velocity"]))
    return fit_block_slider(s["time"], s["wall_vx"], window, info.k, info.m_b, info.sigma)


def fit_table(reader: RunReader, catalog: list[dict] | None = None, notch: bool = True) -> list[dict]:
    """Block-slider fit (thesis Eq. 3) of each slip's wall velocity, one row per slip (:data:`FIT_COLUMNS`).

    half_period: fitted pi/omega [t0] against predicted pi sqrt(m_b/k);
    delta_mu: mu_s - mu_d implied by the fitted amplitude, A sqrt(k m_b)/sigma;
    delta_mu_eq7: static strength minus the mean mu_d(t) of Eq. 7 over the slip.
    """
    if catalog is None:
        catalog = read_catalog(reader)
    info = reader.info
    rows = []
    for entry in catalog:
        fit = fit_slip(reader, entry)
        fr = slip_friction(reader, entry, notch=notch)
        rows.append({
            "number": int(entry["number"]),
            "duration": float(entry["duration"]),
            "half_period": fit.half_period,
            "predicted_half_period": fit.predicted_half_period,
            "half_period_ratio": fit.half_period_ratio,
            "amplitude": fit.amplitude,
            "amplitude_over_Vs": fit.amplitude / info.V_s,
            "delta_mu": fit.delta_mu,
            "static_friction": fr.mu_s,
            "mean_dynamic_friction": fr.mean_mu_d,
            "delta_mu_eq7": fr.mu_s - fr.mean_mu_d,
            "notch_frequency": fr.notch_frequency,
            "r2": fit.r2,
            "nrms": fit.nrms,
            "n_points": fit.n_points,
            "success": bool(fit.success),
            "reason": fit.reason,
            "m_eff": fit.m_eff,
            "m_eff_over_m_b": fit.m_eff / info.m_b,
        })
    return rows


# --------------------------------------------------------------------------- pairs


def fork_dirs(run_dir: Path) -> list[Path]:
    """``RUN/forks/slip_NNN`` directories, in slip order."""
    root = Path(run_dir) / "forks"
    return sorted(p for p in root.glob("slip_*") if p.is_dir()) if root.is_dir() else []


def fork_branches(fork_dir: Path) -> tuple[Path | None, list[Path]]:
    """(drained run dir or None, undrained ``perm_*`` run dirs sorted by permeability)."""
    fork_dir = Path(fork_dir)
    drained = fork_dir / "drained"
    perms = [p for p in fork_dir.glob("perm_*") if (p / "run.h5").is_file()]

    def perm_value(p: Path) -> float:
        try:
            return float(p.name[len("perm_"):])
        except ValueError:
            return math.inf

    return (drained if (drained / "run.h5").is_file() else None), sorted(perms, key=perm_value)


def _wall_series(reader: RunReader) -> WallSeries:
    s = reader.series(["time", "wall_x", "wall_vx", "tau_over_sigma", "porosity"])
    return WallSeries(s["time"], s["wall_x"], s["wall_vx"], s["tau_over_sigma"], s["porosity"])


@dataclass
class ForkPair:
    """One drained/undrained pair: the table row (:data:`PAIR_COLUMNS`) and the classification."""

    row: dict
    result: PairResult
    drained_dir: Path
    undrained_dir: Path


def _r2(fit) -> float:
    return float(fit.r2) if fit is not None else _NAN


def _when(slip, attr: str) -> float:
    return float(getattr(slip, attr)) if slip is not None else _NAN


def pair_definition(info: RunInfo, main: str = "first") -> PairDefinition:
    """The pair definition with this run's detector thresholds."""
    return PairDefinition.for_run(info.slip_params, main=main)


def classify_fork(fork_dir: Path, main: str = "first") -> list[ForkPair]:
    """Classify every undrained branch of ``RUN/forks/slip_NNN`` against its drained branch.

    Uses :func:`~gouge_cli.analysis.pairs.classify_pair` with :func:`pair_definition` (the run's
    detector thresholds; ``main``: "first" or "largest"). Raises :class:`RunStillRunningError`
    when a branch is still running and :class:`NotARunError` when the drained branch is missing.
    """
    fork_dir = Path(fork_dir)
    drained_dir, undrained_dirs = fork_branches(fork_dir)
    if drained_dir is None:
        raise NotARunError(f"{fork_dir} has no drained/run.h5; run `gouge restart` for this slip again")
    pairs = []
    with RunReader(drained_dir) as d:
        info = d.info
        drained = _wall_series(d)
        definition = pair_definition(info, main)
        for udir in undrained_dirs:
            with RunReader(udir) as u:
                undrained = _wall_series(u)
                deborah = u.series(["deborah"])["deborah"]
                uinfo = u.info
            result = classify_pair(drained, undrained, info.V_s, info.k, info.m_b, info.sigma, definition)
            d_main, u_main = result.drained_slip, result.undrained_slip
            fired = [name for name, on in result.criteria.items() if on]
            parent = str(fork_dir.parent.parent)     # parent_run is stored relative to the branch
            row = {
                "run": parent,
                "slip": int(info.fork_slip) if info.fork_slip is not None else _slip_number(fork_dir),
                "branch": udir.name,
                "permeability": uinfo.permeability if uinfo.permeability is not None else _NAN,
                "main": definition.main,
                "type": result.type,
                "base_type": result.base_type,
                "complex": bool(result.complex),
                "criteria": ",".join(fired),
                "undrained_event": result.undrained_event,
                "drained_strength": result.drained_strength,
                "undrained_strength": result.undrained_strength,
                "strength_difference": result.strength_difference,
                "peak_velocity_ratio": result.peak_velocity_ratio,
                "stress_drop_ratio": result.stress_drop_ratio,
                "duration_ratio": result.duration_ratio,
                "drained_peak_over_Vs": result.drained_peak_over_Vs,
                "undrained_peak_over_Vs": result.undrained_peak_over_Vs,
                "n_undrained_slips": len(result.undrained_slips),
                "n_subevents": result.n_subevents,
                "drained_onset": _when(d_main, "onset_time"),
                "drained_end": _when(d_main, "end_time"),
                "undrained_onset": _when(u_main, "onset_time"),
                "undrained_end": _when(u_main, "end_time"),
                "drained_fit_r2": _r2(result.drained_fit),
                "drained_fit_ok": bool(result.drained_fit is not None and result.drained_fit.success),
                "undrained_fit_r2": _r2(result.undrained_fit),
                "deborah_mean": _nan_mean(deborah),
                "note": result.note,
            }
            pairs.append(ForkPair(row, result, drained_dir, udir))
    return pairs


def _slip_number(fork_dir: Path) -> int:
    try:
        return int(Path(fork_dir).name.split("_")[-1])
    except ValueError:
        return -1


def run_pairs(run_dir: Path, strict: bool = False, main: str = "first") -> tuple[list[ForkPair], list[str]]:
    """All pairs under ``RUN/forks`` (compared events chosen by ``main``). Returns (pairs, skipped):
    a fork that cannot be classified (still running, incomplete) is skipped with its reason, or
    raises when ``strict``."""
    pairs, skipped = [], []
    for fork in fork_dirs(run_dir):
        try:
            pairs.extend(classify_fork(fork, main))
        except AnalysisError as exc:
            if strict:
                raise
            skipped.append(str(exc))
    return pairs, skipped


def campaign(pairs: list[ForkPair]) -> dict:
    """Counts per type and undrained/drained ratio statistics over pairs (of one or more runs)."""
    return campaign_summary([p.result for p in pairs])


# --------------------------------------------------------------------------- whole run


@dataclass
class RunAnalysis:
    """Everything `gouge analyze` computes for one run."""

    info: RunInfo
    catalog: list[dict]
    summary: dict
    fits: list[dict]
    pairs: list[ForkPair]
    skipped: list[str]
    notch: bool

    @property
    def pair_rows(self) -> list[dict]:
        return [p.row for p in self.pairs]

    def fit_summary(self) -> dict:
        return summary_statistics(self.fits, ("half_period", "half_period_ratio", "delta_mu",
                                              "mean_dynamic_friction", "delta_mu_eq7", "r2"))

    def to_dict(self) -> dict:
        return {
            "run": str(self.info.run_dir),
            "parameters": {"k": self.info.k, "V_s": self.info.V_s, "sigma": self.info.sigma,
                           "m_b": self.info.m_b, "predicted_half_period": self.info.predicted_half_period,
                           "has_fluid": self.info.has_fluid, "notch": self.notch},
            "catalog": self.catalog,
            "summary": self.summary,
            "fits": self.fits,
            "fit_summary": self.fit_summary(),
            "pairs": self.pair_rows,
            "campaign": campaign(self.pairs) if self.pairs else None,
            "skipped_forks": self.skipped,
        }


def analyze_run(run_dir: Path | str, notch: bool = True, main: str = "first") -> RunAnalysis:
    """Catalog, summary statistics, block-slider fits and fork pairs of one run.

    Raises :class:`NotARunError`, :class:`RunStillRunningError` or :class:`NoSlipsError`.
    """
    with RunReader(run_dir) as reader:
        catalog = read_catalog(reader)
        if not catalog:
            info = reader.info
            raise NoSlipsError(
                f"{info.describe()} has no slips (status {info.status!r}, {info.n_samples} samples): "
                "run it longer (run.duration), load it faster, or lower slips.start_factor")
        rows = catalog_table(reader, catalog)
        fits = fit_table(reader, catalog, notch=notch)
        info = reader.info
    pairs, skipped = run_pairs(info.run_dir, main=main)
    return RunAnalysis(info, rows, summary_statistics(rows), fits, pairs, skipped, notch)


# --------------------------------------------------------------------------- writing


def _write_csv(path: Path, rows: list[dict], columns) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(columns), extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, "") for c in columns})


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    return str(obj)


def _table_to_group(group: h5py.Group, rows: list[dict], columns) -> None:
    group.attrs["columns"] = json.dumps(list(columns))
    for col in columns:
        values = [r.get(col) for r in rows]
        if all(isinstance(v, (bool, np.bool_)) for v in values) and values:
            data = np.asarray(values, dtype=bool)
        elif all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
                 for v in values):
            data = np.asarray(values, dtype=float)
        else:
            data = np.asarray(["" if v is None else str(v) for v in values], dtype=h5py.string_dtype())
        group.create_dataset(col, data=data)


def write_analysis(analysis: RunAnalysis, out_dir: Path | None = None, into_h5: bool = True) -> dict[str, Path]:
    """Write ``RUN/analysis/{catalog,fits[,pairs]}.csv`` and ``summary.json``, and the same
    tables under ``/analysis`` in run.h5 (replaced on each call). Returns the written paths."""
    info = analysis.info
    out_dir = Path(out_dir) if out_dir is not None else info.run_dir / "analysis"
    out_dir.mkdir(parents=True, exist_ok=True)
    written = {}
    _write_csv(out_dir / "catalog.csv", analysis.catalog, CATALOG_COLUMNS)
    written["catalog"] = out_dir / "catalog.csv"
    _write_csv(out_dir / "fits.csv", analysis.fits, FIT_COLUMNS)
    written["fits"] = out_dir / "fits.csv"
    pairs_csv = out_dir / "pairs.csv"
    if analysis.pairs:
        _write_csv(pairs_csv, analysis.pair_rows, PAIR_COLUMNS)
        written["pairs"] = pairs_csv
    elif pairs_csv.exists():
        pairs_csv.unlink()
    summary = {k: v for k, v in analysis.to_dict().items() if k not in ("catalog", "fits", "pairs")}
    (out_dir / "summary.json").write_text(json.dumps(json_safe(summary), indent=2, default=_json_default,
                                                     allow_nan=False))
    written["summary"] = out_dir / "summary.json"
    if into_h5:
        try:
            with h5py.File(info.h5_path, "a") as h5:
                if "analysis" in h5:
                    del h5["analysis"]
                grp = h5.create_group("analysis")
                grp.attrs["created"] = _time.strftime("%Y-%m-%dT%H:%M:%S%z")
                grp.attrs["version"] = __version__
                grp.attrs["notch"] = bool(analysis.notch)
                grp.attrs["summary"] = json.dumps(json_safe(summary), default=_json_default, allow_nan=False)
                _table_to_group(grp.create_group("catalog"), analysis.catalog, CATALOG_COLUMNS)
                _table_to_group(grp.create_group("fits"), analysis.fits, FIT_COLUMNS)
                if analysis.pairs:
                    _table_to_group(grp.create_group("pairs"), analysis.pair_rows, PAIR_COLUMNS)
                document_analysis(grp)
        except OSError as exc:
            # the tables are in the CSV files already; run.h5 is left as it is (read-only, or open elsewhere)
            written["h5_skipped"] = (f"/analysis not written into {info.h5_path} "
                                     f"({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__}); "
                                     "the CSV files hold the same tables")
            return written
        written["h5"] = info.h5_path
    return written


# --------------------------------------------------------------------------- plotting support


def series_envelope(reader: RunReader, names, max_points: int = 6000, chunk: int = 1_000_000,
                    start: int = 0, stop: int | None = None) -> dict[str, np.ndarray]:
    """Series for plotting, reduced to at most ~``max_points`` samples.

    Short series come back whole. Longer ones are split into ``max_points / 2`` bins of
    consecutive samples; each bin gives its min and max (in time order), read in chunks
    of ``chunk`` samples, so peaks survive and memory stays bounded. Always includes
    ``time``. Absent series are omitted.
    """
    stop = reader.info.n_samples if stop is None else stop
    n = max(stop - start, 0)
    names = ["time"] + [x for x in names if x != "time" and reader.has(x)]
    if n <= max_points:
        return {k: v for k, v in reader.series(names, start, stop).items() if v is not None}
    nbins = max_points // 2
    per = int(math.ceil(n / nbins))
    out = {k: [] for k in names}
    step = max(per, (chunk // per) * per)
    for a in range(start, stop, step):
        b = min(a + step, stop)
        block = reader.series(names, a, b)
        m = b - a
        nb = int(math.ceil(m / per))
        pad = nb * per - m
        t = block["time"]
        for name in names:
            y = block[name]
            if pad:
                y = np.concatenate([y, np.full(pad, y[-1])])
            y = y.reshape(nb, per)
            if name == "time":
                tt = np.concatenate([t, np.full(pad, t[-1])]).reshape(nb, per) if pad else t.reshape(nb, per)
                out[name].append(np.column_stack([tt[:, 0], tt[:, -1]]).ravel())
                continue
            imin = np.argmin(np.where(np.isnan(y), np.inf, y), axis=1)
            imax = np.argmax(np.where(np.isnan(y), -np.inf, y), axis=1)
            rows = np.arange(nb)
            lo, hi = y[rows, imin], y[rows, imax]
            first = np.where(imin <= imax, lo, hi)
            second = np.where(imin <= imax, hi, lo)
            out[name].append(np.column_stack([first, second]).ravel())
    return {k: np.concatenate(v) for k, v in out.items()}
