"""The one definition of a drained/undrained pair (thesis Sections 4.2-4.3, Figs. 8-13, Table 3).

A *pair* is the same slip run twice from the same packing: drained (dry) and undrained
(low permeability). Both series cover the same window (from the checkpoint before the
slip). Everything that compares the two branches -- ``gouge restart`` (pair.json),
``gouge analyze`` (pairs.csv), ``gouge plot`` (figure titles and shading) and
``gouge study`` -- calls :func:`classify_pair` with a :class:`PairDefinition`; nothing else
decides which events are compared or what type a pair is.

Rule (all thresholds are fields of :class:`PairDefinition` or of its slip rule, velocities in units of V_s):

* Events: slips found by the run's own :class:`~gouge_cli.model.slip_rule.SlipRule` (its
  thresholds (trigger ``start_factor``, extent ``end_factor``). The *compared* event of each
  branch is its first slip (``main="first"``: the forked slip) or the one with the largest
  slip distance (``main="largest"``).
* Slow slip: an undrained branch with no slip at the trigger is searched again with the
  trigger lowered to ``slow_factor`` (default ``min(2 end_factor, (start_factor+end_factor)/2)``);
  an event found then is compared as a "slow slip below trigger" (criterion ``slow``).
  Without one the pair is ``none`` and the note gives the branch's peak velocity.
* Measures of an event: static strength S = the largest tau/sigma from the series start up
  to the event's onset sample (its time reported beside it); stress drop = tau/sigma at onset
  minus its minimum during the event; peak velocity; duration (between the ``end_factor`` crossings); sub-events.
* Type: ``I`` if S_u < S_d - strength_tol, ``II`` if S_u > S_d + strength_tol, else ``tie``
  (strength_tol = 1e-3 in tau/sigma). Suffix ``-C`` if a criterion of
  :func:`complexity_criteria` fires on the undrained branch, or it is a slow slip.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from enum import Enum

import numpy as np

from .blockslider import BlockSliderFit, fit_block_slider
from ..errors import ConfigError
from ..io.records import unit
from ..model.slip_rule import Slip, SlipRule, WallSeries

__all__ = ["MainEvent", "PairDefinition", "PairResult", "classify_pair", "complexity_criteria", "campaign_summary",
           "PairCounts", "RatioStats",
           "compared_event", "static_strength", "regime", "DRAINED_DE", "UNDRAINED_DE", "SLOW", "CRITERIA"]

_NAN = float("nan")
CRITERIA = ("subevents", "restart", "creep", "fit", "slow")
TYPES = ("I", "II", "I-C", "II-C")
RATIOS = ("peak_velocity_ratio", "stress_drop_ratio", "duration_ratio")
SLOW = "slow slip below trigger"


class MainEvent(str, Enum):
    """The event of each branch a pair compares (``--main``): ``first`` (the forked slip) or
    ``largest`` (the largest slip distance). The one check of the option: :meth:`check`."""

    FIRST = "first"
    LARGEST = "largest"

    @classmethod
    def check(cls, value) -> str:
        """``value`` (a name or a member) as its plain name; ConfigError naming ``--main`` otherwise."""
        try:
            return cls(value).value
        except ValueError:
            raise ConfigError(f"--main = {value!r}: use 'first' (the forked slip) or 'largest'") from None


@dataclass(frozen=True)
class PairDefinition:
    """Every threshold of the pair comparison (velocities as multiples of V_s, strengths in tau/sigma).

    main: "first" (the forked slip) or "largest" (largest slip distance) event of each branch.
    strength_tol: |S_u - S_d| <= strength_tol is a tie.
    slips: the run's slip rule at V_s = 1 (its factors are the thresholds in V_s; :meth:`rule` puts
    in a branch's V_s); :meth:`with_` and :meth:`for_run` take its keys (start_factor, ...) flat.
    slow_factor: lowered trigger for a slow undrained slip (None: min(2 end, (start+end)/2)).
    max_subevents, restart_factor, creep_low_factor, creep_fraction, creep_smooth, min_fit_r2:
    the '-C' criteria of :func:`complexity_criteria`.
    """

    main: str = "first"
    strength_tol: float = 1e-3
    slips: SlipRule = field(default_factory=lambda: SlipRule(1.0))
    slow_factor: float | None = None
    max_subevents: int = 1
    restart_factor: float | None = None
    creep_low_factor: float = 0.5
    creep_fraction: float = 0.5
    creep_smooth: int = 1
    min_fit_r2: float = 0.8

    def __post_init__(self):
        object.__setattr__(self, "main", MainEvent.check(self.main))

    @classmethod
    def for_run(cls, rule: SlipRule | dict, **overrides) -> "PairDefinition":
        """The definition with a run's slip rule (``RunInfo.slip_rule``, or its config values as a
        dict) and overrides (None: kept). TypeError naming a key that is neither a field of the
        definition nor a slip rule key."""
        values = {**(rule.config_values() if isinstance(rule, SlipRule) else rule), **overrides}
        known = [f.name for f in fields(cls) if f.name != "slips"] + list(SlipRule.CONFIG_KEYS)
        unknown = [k for k in values if k not in known]
        if unknown:
            raise TypeError(f"PairDefinition.for_run: unknown key {unknown[0]!r}; the keys are {', '.join(known)}")
        return cls().with_(**{k: v for k, v in values.items() if v is not None})

    def with_(self, **changes) -> "PairDefinition":
        """A copy with fields changed; the slip rule's keys (SlipRule.CONFIG_KEYS) change ``slips``
        (None: kept)."""
        rule = {k: changes.pop(k) for k in SlipRule.CONFIG_KEYS if k in changes}
        return replace(self, slips=self.slips.with_(**rule), **changes)

    def rule(self, V_s: float, start_factor: float | None = None) -> SlipRule:
        """The slip rule of this definition at V_s (``start_factor``: another trigger, e.g. the slow one)."""
        return self.slips.with_(V_s=V_s, start_factor=start_factor)

    @property
    def slow_trigger(self) -> float:
        """Trigger for a slow slip [V_s]."""
        if self.slow_factor is not None:
            return self.slow_factor
        return min(2.0 * self.slips.end_factor, 0.5 * (self.slips.start_factor + self.slips.end_factor))

    def detect(self, s: WallSeries, V_s: float, start_factor: float | None = None) -> list[Slip]:
        return self.rule(V_s, start_factor).detect(s.t, s.v_wall, x_wall=s.x_wall,
                                                   tau_over_sigma=s.tau_over_sigma, porosity=s.porosity)

    def to_dict(self) -> dict:
        """Flat: the definition's fields with the slip rule's keys in place of ``slips`` (pair.json)."""
        own = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "slips"}
        return {**own, **self.slips.config_values(), "slow_trigger": self.slow_trigger}


@dataclass
class PairResult:
    """Outcome of :func:`classify_pair`. Ratios are undrained / drained (compared events).

    undrained_event: "slip", "slow slip below trigger" or "none"; note: one line for people.
    """

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
    undrained_event: str = "slip"
    drained_peak_over_Vs: float = _NAN
    undrained_peak_over_Vs: float = _NAN
    n_subevents: int = 0
    note: str = ""
    definition: dict = field(default_factory=dict)
    drained_strength_time: float = _NAN       # when S_d and S_u were reached (the branches' clock)
    undrained_strength_time: float = _NAN

    def to_dict(self) -> dict:
        return asdict(self)


DRAINED_DE = 0.01      # De below this (two decades under 1: "De << 1") is "drained-like"
UNDRAINED_DE = 1.0     # De at or above this is "undrained"; between the two "partially drained"


def regime(deborah: float) -> str:
    """Name of a fluid branch's drainage from its Deborah number De = l u0 / D (thesis Eq. 4: the time
    for pressure to diffuse over the distance l to the drained walls over the time to generate it):
    "drained-like" for De < DRAINED_DE (the thesis's De << 1, "fully drained"), "undrained" for
    De >= UNDRAINED_DE (its "effectively undrained", De >= 1), "partially drained" between, "unknown"
    without a finite De. The De used is the branch's mean over its compared slip (deborah_slip)."""
    if not math.isfinite(deborah):
        return "unknown"
    if deborah < DRAINED_DE:
        return "drained-like"
    return "undrained" if deborah >= UNDRAINED_DE else "partially drained"


def compared_event(slips: list[Slip], main: str) -> Slip | None:
    """The event a pair compares: the first slip, or the one with the largest slip distance."""
    if not slips:
        return None
    if main == "first":
        return slips[0]
    if main == "largest":
        return max(slips, key=lambda s: s.slip)
    raise ValueError(f"main must be 'largest' or 'first', got {main!r}")


def static_strength(tau_over_sigma, slip: Slip) -> float:
    """Largest tau/sigma from the series start up to and including the slip's onset sample."""
    seg = np.asarray(tau_over_sigma[:slip.onset_index + 1], dtype=float)
    seg = seg[~np.isnan(seg)]
    return float(seg.max()) if seg.size else _NAN


def static_strength_time(t, tau_over_sigma, slip: Slip) -> float:
    """Time (of ``t``) at which :func:`static_strength` is reached: its first sample (NaN if none)."""
    seg = np.asarray(tau_over_sigma[:slip.onset_index + 1], dtype=float)
    if not np.any(np.isfinite(seg)):
        return _NAN
    return float(np.asarray(t)[int(np.nanargmax(seg))])


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
    start_factor: float = SlipRule.start_factor,
    max_subevents: int = 1,
    restart_factor: float | None = None,
    creep_low_factor: float = 0.5,
    creep_fraction: float = 0.5,
    creep_smooth: int = 1,
    min_fit_r2: float = 0.8,
) -> tuple[dict[str, bool], dict[str, float]]:
    """The '-C' criteria on one (undrained) velocity series.

    t, v_wall: shape (n,). Let ``hi = start_factor * V_s``.
    (a) ``subevents``: the main slip has more than ``max_subevents`` sub-events.
    (b) ``restart``: between the first slip's onset and the last slip's end the
        velocity exceeds ``hi``, falls below ``restart_factor * V_s`` (default
        ``start_factor``, i.e. below ``hi``) and exceeds ``hi`` again.
    (c) ``creep``: somewhere in the series the velocity (running mean over
        ``creep_smooth`` samples) stays in ``[creep_low_factor V_s, hi)`` for
        longer than ``creep_fraction`` times the main slip's duration.
    (d) ``fit``: the block-slider fit of the main slip has ``R^2 < min_fit_r2``
        (or failed the fit bar of :func:`~gouge_cli.analysis.blockslider.fit_block_slider`).
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


def _peak(v, V_s: float) -> float:
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) / V_s if v.size else _NAN


def classify_pair(
    drained: WallSeries,
    undrained: WallSeries,
    V_s: float,
    k: float,
    m_b: float,
    sigma: float,
    definition: PairDefinition | None = None,
    **overrides,
) -> PairResult:
    """Classify one drained/undrained pair (thesis Type I / II, suffix -C) by ``definition``.

    ``overrides`` replace fields of the definition (e.g. ``strength_tol=1e-3``, ``main="largest"``,
    or a run's ``start_factor``). See the module docstring for the rule.
    """
    d = (definition or PairDefinition()).with_(**overrides)
    none_criteria = {c: False for c in CRITERIA}
    d_slips = d.detect(drained, V_s)
    u_slips = d.detect(undrained, V_s)
    event = "slip"
    if not u_slips:
        u_slips = d.detect(undrained, V_s, start_factor=d.slow_trigger)
        event = SLOW if u_slips else "none"
    d_main, u_main = compared_event(d_slips, d.main), compared_event(u_slips, d.main)
    d_peak, u_peak = _peak(drained.v_wall, V_s), _peak(undrained.v_wall, V_s)
    if d_main is None or u_main is None:
        if d_main is None:
            note = f"drained branch did not slip in its window (peak {d_peak:.3g} V_s)"
        else:
            note = (f"undrained branch did not move in its window: peak {u_peak:.3g} V_s, below the "
                    f"slow-slip trigger {d.slow_trigger:g} V_s (slip trigger {d.slips.start_factor:g} V_s)")
        return PairResult("none", "none", False, none_criteria, {}, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN,
                          d_main, u_main, u_slips, undrained_event="none" if u_main is None else event,
                          drained_peak_over_Vs=d_main.peak_velocity / V_s if d_main else d_peak,
                          undrained_peak_over_Vs=u_main.peak_velocity / V_s if u_main else u_peak,
                          note=note, definition=d.to_dict())

    s_d = static_strength(drained.tau_over_sigma, d_main)
    s_u = static_strength(undrained.tau_over_sigma, u_main)
    diff = s_u - s_d
    if diff < -d.strength_tol:
        base = "I"
    elif diff > d.strength_tol:
        base = "II"
    else:
        base = "tie"

    d_fit = fit_block_slider(drained.t, drained.v_wall, d_main, k, m_b, sigma)
    u_fit = fit_block_slider(undrained.t, undrained.v_wall, u_main, k, m_b, sigma)
    fired, measures = complexity_criteria(
        undrained.t, undrained.v_wall, u_slips, u_main, u_fit, V_s,
        start_factor=d.slow_trigger if event == SLOW else d.slips.start_factor,
        max_subevents=d.max_subevents, restart_factor=d.restart_factor,
        creep_low_factor=d.creep_low_factor, creep_fraction=d.creep_fraction,
        creep_smooth=d.creep_smooth, min_fit_r2=d.min_fit_r2,
    )
    fired["slow"] = event == SLOW
    is_complex = any(fired.values())
    note = ""
    if event == SLOW:
        note = (f"undrained: {SLOW} (peak {u_main.peak_velocity / V_s:.3g} V_s < trigger "
                f"{d.slips.start_factor:g} V_s)")
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
        undrained_event=event,
        drained_peak_over_Vs=d_main.peak_velocity / V_s,
        undrained_peak_over_Vs=u_main.peak_velocity / V_s,
        n_subevents=u_main.n_subevents,
        note=note,
        definition=d.to_dict(),
        drained_strength_time=static_strength_time(drained.t, drained.tau_over_sigma, d_main),
        undrained_strength_time=static_strength_time(undrained.t, undrained.tau_over_sigma, u_main),
    )


@dataclass(frozen=True)
class RatioStats:
    """Statistics of one undrained/drained ratio [-] over the finite values of classified pairs."""

    n: int = unit("-", "finite values")
    mean: float = unit("-", "their mean")
    median: float = unit("-", "their median")
    std: float = unit("-", "their standard deviation")
    min: float = unit("-", "the smallest")
    max: float = unit("-", "the largest")
    frac_below_1: float = unit("-", "fraction below 1 (undrained smaller)")


def _stats(values: list[float]) -> RatioStats:
    a = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if a.size == 0:
        return RatioStats(0, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN)
    return RatioStats(int(a.size), float(a.mean()), float(np.median(a)), float(a.std()), float(a.min()),
                      float(a.max()), float(np.mean(a < 1.0)))


@dataclass(frozen=True)
class PairCounts:
    """Counts per type and statistics of the undrained/drained ratios of a set of pairs
    (:func:`campaign_summary`); :func:`~gouge_cli.io.records.plain` gives its JSON form."""

    n: int = unit("-", "pairs")
    counts: dict = unit("-", "pairs per type: I, II, I-C, II-C, tie, tie-C, none (and failed, if any)")
    n_type_I: int = unit("-", "Type I pairs, complex or not")
    n_type_II: int = unit("-", "Type II pairs, complex or not")
    n_tie: int = unit("-", "ties, complex or not")
    n_complex: int = unit("-", "complex classified pairs")
    n_slow: int = unit("-", "classified pairs whose undrained event is a slow slip below the trigger")
    criteria: dict = unit("-", "classified pairs each complexity criterion fired on")
    ratios: dict = unit("-", "RatioStats of each ratio (RATIOS) over the classified pairs")


def campaign_summary(results: list[PairResult]) -> PairCounts:
    """Counts per type and statistics of the undrained/drained ratios (ratio statistics over finite
    values of classified pairs): counts over {"I", "II", "I-C", "II-C", "tie", "tie-C", "none"},
    criteria {name: count}, ratios {ratio name: :class:`RatioStats`}."""
    labels = TYPES + ("tie", "tie-C", "none")
    counts = {lab: 0 for lab in labels}
    for r in results:
        counts[r.type] = counts.get(r.type, 0) + 1
    classified = [r for r in results if r.base_type not in ("none", "failed")]
    return PairCounts(
        n=len(results),
        counts=counts,
        n_type_I=counts["I"] + counts["I-C"],
        n_type_II=counts["II"] + counts["II-C"],
        n_tie=counts["tie"] + counts["tie-C"],
        n_complex=sum(1 for r in classified if r.complex),
        n_slow=sum(1 for r in classified if r.undrained_event == SLOW),
        criteria={c: sum(1 for r in classified if r.criteria.get(c, False)) for c in CRITERIA},
        ratios={name: _stats([getattr(r, name) for r in classified]) for name in RATIOS},
    )
