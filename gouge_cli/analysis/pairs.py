"""Drained/undrained pair classification (thesis Sections 4.2-4.3, Figs. 8-13).

A *pair* is the same slip run twice from the same packing: drained (dry or
very permeable) and undrained (low permeability). Both series cover the same
window (restart before the drained slip until after it). See
:func:`classify_pair` for the rule.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .blockslider import BlockSliderFit, fit_block_slider
from ..detector import Slip, WallSeries, detect_slips

__all__ = ["PairResult", "classify_pair", "complexity_criteria", "campaign_summary"]

_NAN = float("nan")
CRITERIA = ("subevents", "restart", "creep", "fit")
TYPES = ("I", "II", "I-C", "II-C")
RATIOS = ("peak_velocity_ratio", "stress_drop_ratio", "duration_ratio")


@dataclass
class PairResult:
    """Outcome of :func:`classify_pair`. Ratios are undrained / drained (main slips)."""

    type: str
    base_type: str
    complex: bool
    criteria: dict[str, bool]
    measures: dict[str, float]
    drained_strength: float
    undrained_strength: float
    strength_difference: float
    peak_velocity_ratio: float
    stress_drop_ratio: float
    duration_ratio: float
    drained_slip: Slip | None
    undrained_slip: Slip | None
    undrained_slips: list[Slip] = field(default_factory=list)
    drained_fit: BlockSliderFit | None = None
    undrained_fit: BlockSliderFit | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def _main(slips: list[Slip], main: str) -> Slip | None:
    if not slips:
        return None
    if main == "first":
        return slips[0]
    if main == "largest":
        return max(slips, key=lambda s: s.slip)
    raise ValueError(f"main must be 'largest' or 'first', got {main!r}")


def _strength_before(tau: np.ndarray, slip: Slip) -> float:
    seg = np.asarray(tau[:slip.onset_index + 1], dtype=float)
    seg = seg[~np.isnan(seg)]
    return float(seg.max()) if seg.size else _NAN


def _ratio(a: float, b: float) -> float:
    return a / b if b != 0 and not math.isnan(b) else _NAN


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return edges[0::2], edges[1::2] - 1


def complexity_criteria(
    t,
    v_wall,
    slips: list[Slip],
    main_slip: Slip,
    fit: BlockSliderFit | None,
    V_s: float,
    *,
    start_factor: float = 10.0,
    max_subevents: int = 1,
    restart_factor: float | None = None,
    creep_low_factor: float = 0.5,
    creep_fraction: float = 0.5,
    creep_smooth: int = 1,
    min_fit_r2: float = 0.8,
) -> tuple[dict[str, bool], dict[str, float]]:
    """The four '-C' criteria on one (undrained) velocity series.

    t, v_wall: shape (n,). Let ``hi = start_factor * V_s``.
    (a) ``subevents``: the main slip has more than ``max_subevents`` sub-events.
    (b) ``restart``: between the first slip's onset and the last slip's end the
        velocity exceeds ``hi``, falls below ``restart_factor * V_s`` (default
        ``start_factor``, i.e. below ``hi``) and exceeds ``hi`` again.
    (c) ``creep``: somewhere in the series the velocity (running mean over
        ``creep_smooth`` samples) stays in ``[creep_low_factor V_s, hi)`` for
        longer than ``creep_fraction`` times the main slip's duration.
    (d) ``fit``: the block-slider fit of the main slip has ``R^2 < min_fit_r2``
        (or failed).
    Returns ``(fired, measures)``; measures holds n_subevents, n_restarts,
    creep_time and fit_r2.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(v_wall, dtype=float)
    hi = start_factor * V_s
    restart_level = (start_factor if restart_factor is None else restart_factor) * V_s

    n_sub = main_slip.n_subevents

    i0, i1 = slips[0].onset_index, slips[-1].end_index
    w = v[i0:i1 + 1]
    seg_start, seg_end = _runs(w >= restart_level)
    n_bursts = sum(1 for a, b in zip(seg_start, seg_end) if w[a:b + 1].max() >= hi)
    n_restarts = max(n_bursts - 1, 0)

    vs = v
    if creep_smooth > 1:
        vs = np.convolve(v, np.ones(creep_smooth) / creep_smooth, mode="same")
    c_start, c_end = _runs((vs >= creep_low_factor * V_s) & (vs < hi))
    creep_time = float(max((t[b] - t[a] for a, b in zip(c_start, c_end)), default=0.0))

    r2 = fit.r2 if (fit is not None and fit.success) else _NAN
    fired = {
        "subevents": n_sub > max_subevents,
        "restart": n_restarts > 0,
        "creep": creep_time > creep_fraction * main_slip.duration,
        "fit": not (r2 >= min_fit_r2),
    }
    measures = {"n_subevents": float(n_sub), "n_restarts": float(n_restarts),
                "creep_time": creep_time, "fit_r2": float(r2)}
    return fired, measures


def classify_pair(
    drained: WallSeries,
    undrained: WallSeries,
    V_s: float,
    k: float,
    m_b: float,
    sigma: float,
    *,
    strength_tol: float = 1e-4,
    main: str = "largest",
    max_subevents: int = 1,
    restart_factor: float | None = None,
    creep_low_factor: float = 0.5,
    creep_fraction: float = 0.5,
    creep_smooth: int = 1,
    min_fit_r2: float = 0.8,
    start_factor: float = 10.0,
    end_factor: float = 2.0,
    **detect_kwargs,
) -> PairResult:
    """Classify one drained/undrained pair (thesis Type I / II, suffix -C).

    Slips are found in both series with :func:`detect_slips` (same thresholds;
    ``detect_kwargs`` pass through). The *main* slip of each is the one with the
    largest slip distance (``main="first"``: the first). Static strength = the
    largest tau/sigma from the series start up to the main slip's onset.

    * Type ``I`` if ``S_u < S_d - strength_tol``, ``II`` if ``S_u > S_d + strength_tol``,
      otherwise ``tie`` (``S_u``, ``S_d``: undrained, drained static strengths).
    * Suffix ``-C`` if any criterion of :func:`complexity_criteria` fires on the
      undrained series: (a) main slip has > ``max_subevents`` (1) sub-events;
      (b) velocity falls below ``restart_factor V_s`` (default ``start_factor V_s``)
      and exceeds ``start_factor V_s`` again between the first onset and last end;
      (c) velocity in ``[creep_low_factor V_s, start_factor V_s)`` = [0.5, 10) V_s
      for longer than ``creep_fraction`` (0.5) of the main slip duration;
      (d) block-slider fit ``R^2 < min_fit_r2`` (0.8).
    * No slip in either series: type ``none``.

    Ratios (undrained / drained) of peak velocity, stress drop and duration of
    the main slips are returned with the criteria that fired.
    """
    kw = dict(start_factor=start_factor, end_factor=end_factor, **detect_kwargs)

    def detect(s: WallSeries) -> list[Slip]:
        return detect_slips(s.t, s.v_wall, V_s, x_wall=s.x_wall,
                            tau_over_sigma=s.tau_over_sigma, porosity=s.porosity, **kw)

    d_slips, u_slips = detect(drained), detect(undrained)
    d_main, u_main = _main(d_slips, main), _main(u_slips, main)
    if d_main is None or u_main is None:
        return PairResult("none", "none", False, {c: False for c in CRITERIA}, {},
                          _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, d_main, u_main, u_slips)

    s_d = _strength_before(np.asarray(drained.tau_over_sigma), d_main)
    s_u = _strength_before(np.asarray(undrained.tau_over_sigma), u_main)
    diff = s_u - s_d
    if diff < -strength_tol:
        base = "I"
    elif diff > strength_tol:
        base = "II"
    else:
        base = "tie"

    d_fit = fit_block_slider(drained.t, drained.v_wall, d_main, k, m_b, sigma)
    u_fit = fit_block_slider(undrained.t, undrained.v_wall, u_main, k, m_b, sigma)
    fired, measures = complexity_criteria(
        undrained.t, undrained.v_wall, u_slips, u_main, u_fit, V_s,
        start_factor=start_factor, max_subevents=max_subevents,
        restart_factor=restart_factor, creep_low_factor=creep_low_factor,
        creep_fraction=creep_fraction, creep_smooth=creep_smooth, min_fit_r2=min_fit_r2,
    )
    is_complex = any(fired.values())
    return PairResult(
        type=base + ("-C" if is_complex else ""),
        base_type=base,
        complex=is_complex,
        criteria=fired,
        measures=measures,
        drained_strength=s_d,
        undrained_strength=s_u,
        strength_difference=diff,
        peak_velocity_ratio=_ratio(u_main.peak_velocity, d_main.peak_velocity),
        stress_drop_ratio=_ratio(u_main.stress_drop, d_main.stress_drop),
        duration_ratio=_ratio(u_main.duration, d_main.duration),
        drained_slip=d_main,
        undrained_slip=u_main,
        undrained_slips=u_slips,
        drained_fit=d_fit,
        undrained_fit=u_fit,
    )


def _stats(values: list[float]) -> dict[str, float]:
    a = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if a.size == 0:
        return {"n": 0, "mean": _NAN, "median": _NAN, "std": _NAN, "min": _NAN,
                "max": _NAN, "frac_below_1": _NAN}
    return {"n": int(a.size), "mean": float(a.mean()), "median": float(np.median(a)),
            "std": float(a.std()), "min": float(a.min()), "max": float(a.max()),
            "frac_below_1": float(np.mean(a < 1.0))}


def campaign_summary(results: list[PairResult]) -> dict:
    """Counts per type and statistics of the undrained/drained ratios.

    Returns ``{"n", "counts": {"I", "II", "I-C", "II-C", "tie", "tie-C", "none"},
    "n_type_I", "n_type_II", "n_complex", "criteria": {name: count},
    "ratios": {ratio name: {n, mean, median, std, min, max, frac_below_1}}}``
    (ratio statistics over finite values of classified pairs).
    """
    labels = TYPES + ("tie", "tie-C", "none")
    counts = {lab: 0 for lab in labels}
    for r in results:
        counts[r.type] = counts.get(r.type, 0) + 1
    classified = [r for r in results if r.base_type != "none"]
    return {
        "n": len(results),
        "counts": counts,
        "n_type_I": counts["I"] + counts["I-C"],
        "n_type_II": counts["II"] + counts["II-C"],
        "n_complex": sum(1 for r in classified if r.complex),
        "criteria": {c: sum(1 for r in classified if r.criteria.get(c, False))
                     for c in CRITERIA},
        "ratios": {name: _stats([getattr(r, name) for r in classified]) for name in RATIOS},
    }
