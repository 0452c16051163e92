"""A run's slips as tables: the catalog (stored /slips or detected from the series with the run's
own thresholds), per-slip windows, friction and block-slider fits (thesis Eq. 3), summary
statistics, and series reduced for plotting. Reads run files through io.runreader.RunReader only."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ..model.slip_rule import WallSeries
from ..errors import NotARunError, SlipNotFoundError
from ..io.runreader import RunReader
from ..io.slipcatalog import SlipEntry, read_slips
from .blockslider import BlockSliderFit, fit_block_slider
from .friction import dynamic_friction, estimate_natural_frequency, mean_dynamic_friction, notch_filter
from .pairs import regime
from ..units import ResultUnits

_NAN = float("nan")


CATALOG_COLUMNS = (
    "number", "onset_time", "end_time", "onset_clock", "duration", "slip", "static_strength", "stress_drop",
    "peak_velocity_over_Vs", "mean_velocity_over_Vs", "recurrence", "porosity_change", "n_subevents", "deborah",
    "regime", "pressure_min_over_sigma", "pressure_max_over_sigma", "checkpoint",
    "onset_time_s", "duration_s", "slip_m", "stress_drop_MPa", "peak_velocity_m_s",
)



SUMMARY_COLUMNS = (
    "duration", "slip", "static_strength", "stress_drop", "peak_velocity_over_Vs",
    "mean_velocity_over_Vs", "recurrence", "porosity_change", "deborah",
)



FIT_COLUMNS = (
    "number", "duration", "half_period", "predicted_half_period", "half_period_ratio",
    "amplitude_over_Vs", "delta_mu", "static_friction", "mean_dynamic_friction",
    "delta_mu_eq7", "notch_frequency", "r2", "nrms", "n_points", "success", "verdict", "reason",
    "m_eff_over_m_b", "duration_s", "half_period_s",
)



def _detected_catalog(reader: RunReader) -> list[SlipEntry]:
    s = reader.series(["time", "wall_x", "wall_vx", "tau_over_sigma", "porosity"])
    if s["wall_vx"] is None:
        raise NotARunError(f"{reader.info.h5_path} has no /series/wall_vx")
    slips = reader.info.slip_rule.detect(s["time"], s["wall_vx"], x_wall=s["wall_x"],
                                         tau_over_sigma=s["tau_over_sigma"], porosity=s["porosity"])
    return [SlipEntry.from_slip(slip, number) for number, slip in enumerate(slips, start=1)]



def read_catalog(reader: RunReader, detect: bool = False) -> list[SlipEntry]:
    """The run's slips (the /slips catalog written while it ran).

    Runs without a /slips group (or ``detect=True``) are scanned with
    :meth:`~gouge_cli.model.slip_rule.SlipRule.detect` with the run's own rule.
    """
    catalog = None if detect else read_slips(reader.h5)
    return _detected_catalog(reader) if catalog is None else catalog



def slip_window(reader: RunReader, entry: SlipEntry, pad: float = 0.0) -> tuple[int, int, int, int]:
    """Sample indices of one slip: ``(i0, i1, j0, j1)``.

    ``i0``: first sample at or after the onset; ``i1``: last sample at or before the end
    (the detector's onset and end samples); ``[j0, j1)``: the slice to read, widened
    by ``pad`` slip durations on each side.
    """
    t_on, t_end = entry.onset_time, entry.end_time
    i0 = reader.index_at_or_after(t_on)
    i1 = max(reader.index_at_or_before(t_end), i0)
    width = pad * (t_end - t_on)
    j0 = max(reader.index_at_or_before(t_on - width), 0) if pad > 0 else i0
    j1 = min(reader.index_at_or_after(t_end + width) + 1, reader.info.n_samples) if pad > 0 else i1 + 1
    j1 = max(j1, min(i1 + 2, reader.info.n_samples))
    return i0, i1, min(j0, i0), j1



def find_slip(catalog: list[SlipEntry], number: int) -> SlipEntry:
    for entry in catalog:
        if entry.number == number:
            return entry
    listed = ", ".join(str(e.number) for e in catalog) or "none"
    raise SlipNotFoundError(f"no slip number {number}; the run has slips {listed}")



def nan_mean(a) -> float:
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



def catalog_table(reader: RunReader, catalog: list[SlipEntry] | None = None) -> list[dict]:
    """One row per slip with :data:`CATALOG_COLUMNS`, each quantity in its one unit
    (:class:`~gouge_cli.units.ResultUnits`) and the main ones again in SI (``*_s``, ``*_m``, ``*_MPa``,
    ``*_m_s``, from the run's scales).

    onset_time, end_time: t0 since loading began (the time origin of every command, file and
    figure); onset_clock: the same onset on the stored clock (since compaction began);
    static_strength: tau/sigma before the onset; stress_drop: drop of tau/sigma; velocities over
    V_s; recurrence: onset minus the previous onset [t0] (NaN for the first); deborah: mean of the
    Deborah-number series over the slip samples (NaN for a dry run) and regime its name
    (:func:`~gouge_cli.analysis.pairs.regime`; "dry" for a dry run); pressure_min/max_over_sigma:
    extremes of the pore-pressure series over the slip [sigma].
    """
    if catalog is None:
        catalog = read_catalog(reader)
    V_s, sigma = reader.info.V_s, reader.info.sigma
    units = ResultUnits.of_run(reader.info.config, V_s, sigma)
    fluid_names = ("deborah", "pressure_min", "pressure_max")
    has_fluid_series = any(reader.has(n) for n in fluid_names)
    rows, previous = [], None
    origin = reader.time_offset()
    for entry in catalog:
        onset = entry.onset_time
        deborah = p_min = p_max = _NAN
        if has_fluid_series:
            i0, i1, _, _ = slip_window(reader, entry)
            s = reader.series(fluid_names, i0, i1 + 1)
            deborah = nan_mean(s["deborah"])
            p_min = _nan_ext(s["pressure_min"], np.min)
            p_max = _nan_ext(s["pressure_max"], np.max)
        peak, mean = entry.peak_velocity, entry.mean_velocity
        duration, drop = entry.duration, entry.stress_drop
        rows.append({
            "number": entry.number,
            "onset_time": onset - origin,
            "end_time": entry.end_time - origin,
            "onset_clock": onset,
            "duration": duration,
            "slip": entry.slip,
            "static_strength": entry.static_strength,
            "stress_drop": drop,
            "peak_velocity_over_Vs": peak / V_s,
            "mean_velocity_over_Vs": mean / V_s,
            "recurrence": onset - previous if previous is not None else _NAN,
            "porosity_change": entry.porosity_change,
            "n_subevents": entry.n_subevents,
            "deborah": deborah,
            "regime": regime(deborah) if reader.info.has_fluid else "dry",
            "pressure_min_over_sigma": p_min / sigma,
            "pressure_max_over_sigma": p_max / sigma,
            "checkpoint": entry.checkpoint,
            "onset_time_s": (onset - origin) * units.t0_s,
            "duration_s": duration * units.t0_s,
            "slip_m": entry.slip * units.d_m,
            "stress_drop_MPa": drop * units.sigma_MPa,
            "peak_velocity_m_s": peak / V_s * units.V_s_m_s,
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



def slip_friction(reader: RunReader, entry: SlipEntry, notch: bool = True, pad: float = 0.5) -> SlipFriction:
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
    span = (entry.onset_time, entry.end_time)
    mean_mu_d = mean_dynamic_friction(t, filtered if filtered is not None else mu, span)
    return SlipFriction(
        number=entry.number, t=t, v_wall=v, tau_over_sigma=tau, friction=mu, filtered=filtered,
        notch_frequency=freq, onset_time=span[0], end_time=span[1],
        mu_s=entry.static_strength, mean_mu_d=mean_mu_d, drained=not info.has_fluid,
        note=note, pressure=pressure)



def _fit_window(entry: SlipEntry, onset_index: int, end_index: int) -> SimpleNamespace:
    return SimpleNamespace(onset_index=onset_index, end_index=end_index, onset_time=entry.onset_time,
                           duration=entry.duration, peak_velocity=entry.peak_velocity)


def fit_slip(reader: RunReader, entry: SlipEntry) -> BlockSliderFit:
    """Fit thesis Eq. 3 to the wall velocity between one slip's onset and end samples."""
    info = reader.info
    i0, i1, j0, j1 = slip_window(reader, entry)
    s = reader.series(["time", "wall_vx"], j0, j1)
    return fit_block_slider(s["time"], s["wall_vx"], _fit_window(entry, i0 - j0, i1 - j0), info.k, info.m_b, info.sigma)


NOTCH_ABOVE = 12.0      # the layer's natural vibration is sought above this many times f_s = sqrt(k/m_b)/2pi
NOTCH_Q = 3.0           # quality factor of its notch
NOTCH_PAD = 0.6         # slip durations of series on each side, for the filter's edges


@dataclass
class NotchedFit:
    """A slip's Eq. 3 fit refitted after the layer's natural vibration is notched out of the wall
    velocity: a diagnostic next to the fit itself (the thesis calls such fluctuations "an artifact
    that Equation 3 does not account for", Sec. II, and traces them to the layer's natural
    vibration, Sec. 4.1); the study's statistics use the unfiltered fit."""

    fit: BlockSliderFit           # Eq. 3 refitted to the notched velocity over the same samples
    natural_frequency: float      # [1/t0] spectral peak of the plain fit's residual above NOTCH_ABOVE f_s
    notched: np.ndarray           # (n,) [v0] the given wall velocity with that vibration notched (q = NOTCH_Q)


def notched_refit(t, v, entry: SlipEntry, fit: BlockSliderFit, k: float, m_b: float,
                  sigma: float) -> NotchedFit | None:
    """:class:`NotchedFit` of a slip (catalog entry: onset_time, end_time, duration,
    peak_velocity) from its wall velocity v(t) (shape (n,), uniform cadence, covering the slip)
    and its plain Eq. 3 fit; None (no diagnostic) when that fit failed the bar, the slip has
    fewer than 16 samples, or the series is too coarse to hold a band above NOTCH_ABOVE f_s."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    inside = (t >= entry.onset_time) & (t <= entry.end_time)
    idx = np.flatnonzero(inside)
    if not fit.success or idx.size < 16:
        return None
    residual = v[inside] - fit.amplitude * np.sin(fit.omega * (t[inside] - fit.t0))
    try:
        f_nat = estimate_natural_frequency(t[inside], residual,
                                           f_min=NOTCH_ABOVE * math.sqrt(k / m_b) / (2.0 * math.pi))
        notched, _ = notch_filter(t, v, f_nat, NOTCH_Q)
    except ValueError:
        return None
    refit = fit_block_slider(t, notched, _fit_window(entry, int(idx[0]), int(idx[-1])), k, m_b, sigma)
    return NotchedFit(refit, f_nat, notched)


def fit_slip_notched(reader: RunReader, entry: SlipEntry, fit: BlockSliderFit | None = None) -> NotchedFit | None:
    """:func:`notched_refit` of one slip of a run over its slip_window with NOTCH_PAD durations each
    side (``fit``: its :func:`fit_slip`, if already made)."""
    info = reader.info
    fit = fit if fit is not None else fit_slip(reader, entry)
    _, _, j0, j1 = slip_window(reader, entry, pad=NOTCH_PAD)
    s = reader.series(["time", "wall_vx"], j0, j1)
    return notched_refit(s["time"], s["wall_vx"], entry, fit, info.k, info.m_b, info.sigma)



def fit_table(reader: RunReader, catalog: list[SlipEntry] | None = None, notch: bool = True) -> list[dict]:
    """Block-slider fit (thesis Eq. 3) of each slip's wall velocity, one row per slip (:data:`FIT_COLUMNS`).

    half_period: fitted pi/omega [t0] against predicted pi sqrt(m_b/k);
    delta_mu: mu_s - mu_d implied by the fitted amplitude, A sqrt(k m_b)/sigma;
    delta_mu_eq7: static strength minus the mean mu_d(t) of Eq. 7 over the slip;
    verdict: "holds", "failed" or "inapplicable" (BlockSliderFit.verdict) and reason: why not
    (empty when it holds); the fitted numbers of a fit that does not hold are kept, marked so.
    """
    if catalog is None:
        catalog = read_catalog(reader)
    info = reader.info
    t0_s = ResultUnits.of_run(info.config, info.V_s, info.sigma).t0_s
    rows = []
    for entry in catalog:
        fit = fit_slip(reader, entry)
        fr = slip_friction(reader, entry, notch=notch)
        rows.append({
            "number": entry.number,
            "duration": entry.duration,
            "half_period": fit.half_period,
            "predicted_half_period": fit.predicted_half_period,
            "half_period_ratio": fit.half_period_ratio,
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
            "verdict": fit.verdict,
            "reason": fit.verdict_reason,
            "m_eff_over_m_b": fit.m_eff / info.m_b,
            "duration_s": entry.duration * t0_s,
            "half_period_s": fit.half_period * t0_s,
        })
    return rows



def wall_series(reader: RunReader) -> WallSeries:
    s = reader.series(["time", "wall_x", "wall_vx", "tau_over_sigma", "porosity"])
    return WallSeries(s["time"], s["wall_x"], s["wall_vx"], s["tau_over_sigma"], s["porosity"])



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
