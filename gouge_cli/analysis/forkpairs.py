"""Drained/undrained fork pairs of a run: the forks under RUN/forks/slip_NNN/, their first slips
classified with the pair definition of analysis.pairs, and the campaign summary over them."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Callable
from pathlib import Path

import numpy as np

from ..errors import AnalysisError, BranchInterruptedError, DamagedFileError, NotARunError, RunStillRunningError
from ..io.layout import ForkLayout, RunLayout
from ..io.records import plain, unit
from ..io.runreader import RunInfo, RunReader
from .catalog import nan_mean, wall_series
from .pairs import (DRAINED_DE, UNDRAINED_DE, PairCounts, PairDefinition, PairResult,  # noqa: F401
                    campaign_summary, classify_pair, regime)

_NAN = float("nan")


@dataclass(frozen=True)
class Mechanism:
    """The pair's test of the pressure equation (:func:`_mechanism`): dilations eps_v [-], pressures [E],
    times [t0]."""

    drained_dilation: float
    undrained_dilation: float
    pressure_peak: float
    undrained_pressure: float
    diffusion_time: float
    onset_window: float
    pressure_from_rate: float


@dataclass(frozen=True)
class PairMeasures:
    """What classify_fork measures of one pair beside its PairResult: the branch's identity
    (parent run, slip, branch folder, kappa_c [d^2], filter width and cell size [d], compared event
    ``main``), ``origin`` (the stored clock when loading began [t0]), ``failure`` ("" or which
    branch failed), its Deborah numbers [-] and regime, and the :class:`Mechanism`."""

    run: str
    slip: int
    branch: str
    permeability: float
    filter_width: float
    cell_size: float
    main: str
    origin: float
    failure: str
    deborah_mean: float
    deborah_slip: float
    regime: str
    deborah_onset: float
    deborah_max: float
    deborah_drained: float
    mechanism: Mechanism


@dataclass(frozen=True)
class Column:
    """One column of the pair table: name, unit (docs/physics/units.md symbols; '-' for ratios,
    counts and labels), one line of description, and its value from (PairResult, PairMeasures)."""

    name: str
    unit: str
    doc: str
    get: Callable[[PairResult, PairMeasures], Any]


def fired_criteria(r: PairResult) -> str:
    """The complexity criteria that fired on the pair, comma-separated ("" for none)."""
    return ",".join(name for name, on in r.criteria.items() if on)


def _fit_reason(r: PairResult) -> str:
    return "; ".join(f"{b}: {f.verdict_reason}" for b, f in (("drained", r.drained_fit), ("undrained", r.undrained_fit))
                     if f is not None and f.verdict_reason)


def _result(name: str, unit: str, doc: str) -> Column:
    """A column that is the PairResult's field `name`."""
    return Column(name, unit, doc, lambda r, m: getattr(r, name))


def _measured(name: str, unit: str, doc: str) -> Column:
    """A column that is the PairMeasures' field `name`."""
    return Column(name, unit, doc, lambda r, m: getattr(m, name))


def _mech(name: str, unit: str, doc: str) -> Column:
    """A column that is the Mechanism's field `name`."""
    return Column(name, unit, doc, lambda r, m: getattr(m.mechanism, name))


# The pair row, in the order of its keys (pair.json); adding a pair metric is one line here.
PAIR_TABLE = (
    _measured("run", "-", "parent run directory"),
    _measured("slip", "-", "slip number the fork starts before"),
    _measured("branch", "-", "undrained branch folder (perm_K)"),
    _measured("permeability", "d^2", "kappa_c of the undrained branch"),
    _measured("filter_width", "d", "fluid.filter_width of the undrained branch"),
    _measured("cell_size", "d", "pressure grid spacing of the undrained branch"),
    _measured("main", "-", "compared event: first or largest slip"),
    _result("type", "-", "pair type (analysis.pairs), or failed"),
    _result("base_type", "-", "type before the complex mark"),
    Column("complex", "-", "whether the pair is complex", lambda r, m: bool(r.complex)),
    Column("criteria", "-", "criteria that fired, comma-separated", lambda r, m: fired_criteria(r)),
    _result("undrained_event", "-", "slip, slow slip below trigger, none (or failed)"),
    _result("drained_strength", "sigma", "static strength of the drained compared slip"),
    _result("undrained_strength", "sigma", "static strength of the undrained compared slip"),
    _result("strength_difference", "sigma", "undrained minus drained strength"),
    Column("drained_strength_time", "t0", "when S_d, the drained maximum compared, was reached, since loading began",
           lambda r, m: r.drained_strength_time - m.origin),
    Column("undrained_strength_time", "t0", "when S_u was reached, since loading began",
           lambda r, m: r.undrained_strength_time - m.origin),
    _result("peak_velocity_ratio", "-", "undrained / drained peak wall velocity"),
    _result("stress_drop_ratio", "-", "undrained / drained stress drop"),
    _result("duration_ratio", "-", "undrained / drained slip duration"),
    _result("drained_peak_over_Vs", "V_s", "drained peak wall velocity"),
    _result("undrained_peak_over_Vs", "V_s", "undrained peak wall velocity"),
    Column("n_undrained_slips", "-", "slips of the undrained branch", lambda r, m: len(r.undrained_slips)),
    _result("n_subevents", "-", "sub-events of the undrained compared slip"),
    Column("drained_onset", "t0", "drained compared slip's onset since loading began",
           lambda r, m: _when(r.drained_slip, "onset_time", m.origin)),
    Column("drained_end", "t0", "its end since loading began", lambda r, m: _when(r.drained_slip, "end_time", m.origin)),
    Column("undrained_onset", "t0", "undrained compared slip's onset since loading began",
           lambda r, m: _when(r.undrained_slip, "onset_time", m.origin)),
    Column("undrained_end", "t0", "its end since loading began",
           lambda r, m: _when(r.undrained_slip, "end_time", m.origin)),
    Column("drained_fit_r2", "-", "R^2 of the drained Eq. 3 fit", lambda r, m: _r2(r.drained_fit)),
    Column("drained_fit_verdict", "-", "holds, failed, inapplicable or none", lambda r, m: _verdict(r.drained_fit)),
    Column("undrained_fit_r2", "-", "R^2 of the undrained Eq. 3 fit", lambda r, m: _r2(r.undrained_fit)),
    Column("undrained_fit_verdict", "-", "holds, failed, inapplicable or none",
           lambda r, m: _verdict(r.undrained_fit)),
    Column("fit_reason", "-", "why a fit does not hold, per branch", lambda r, m: _fit_reason(r)),
    _measured("deborah_mean", "-", "mean De of the undrained branch"),
    _measured("deborah_slip", "-", "mean De over the undrained compared slip"),
    _measured("regime", "-", "drainage regime of De (deborah_slip, else deborah_mean)"),
    _measured("deborah_onset", "-", "De at the undrained onset"),
    _measured("deborah_max", "-", "largest De over the undrained slip"),
    _measured("deborah_drained", "-", "De with the drained twin's peak speed (slip_deborah)"),
    _mech("drained_dilation", "-", "drained eps_v from the fork to its onset"),
    _mech("undrained_dilation", "-", "undrained eps_v from the fork to its onset"),
    _mech("pressure_peak", "E", "undrained layer-mean pressure of largest magnitude before its onset"),
    _mech("undrained_pressure", "E", "|eps_v| / (beta phi) of the drained twin's strain"),
    _mech("diffusion_time", "t0", "t_D = l^2 / D, l half the layer thickness"),
    _mech("onset_window", "t0", "the fork to the undrained onset"),
    _mech("pressure_from_rate", "E", "pressure the undrained strain rate sustains (rate_pressure)"),
    _result("note", "-", "one line for people"),
    Column("status", "-", "finished or failed", lambda r, m: FAILED if m.failure else "finished"),
)
_LEAD = ("run", "slip", "branch", "permeability", "filter_width", "cell_size", "regime", "deborah_slip", "deborah_mean")
# pairs.csv's columns: the identifying ones first, then the rest in PAIR_TABLE's order
PAIR_COLUMNS = _LEAD + tuple(c.name for c in PAIR_TABLE if c.name not in _LEAD)
PAIR_UNITS = {c.name: c.unit for c in PAIR_TABLE}


def pair_row(result: PairResult, measured: PairMeasures) -> dict:
    """One pair's row, {column name: value} in PAIR_TABLE's order (pair.json, pairs.csv)."""
    return {c.name: c.get(result, measured) for c in PAIR_TABLE}


FAILED = "failed"       # type and base_type of a pair whose branch failed (status 'failed: <physics message>')



def fork_dirs(run_dir: Path) -> list[Path]:
    """``RUN/forks/slip_NNN`` directories, in slip order."""
    return RunLayout(run_dir).fork_dirs()


def fork_branches(fork_dir: Path) -> tuple[Path | None, list[Path]]:
    """(drained run dir or None, undrained ``perm_*`` run dirs sorted by permeability)."""
    return ForkLayout(fork_dir).branches()


@dataclass(frozen=True)
class ForkPair:
    """One drained/undrained pair: the classification (:class:`PairResult`), what was measured beside
    it (:class:`PairMeasures`) and the two branch folders. Its table row (:attr:`row`) is built
    from these by :data:`PAIR_TABLE` only."""

    result: PairResult
    measured: PairMeasures
    drained_dir: Path
    undrained_dir: Path

    @cached_property
    def row(self) -> dict:
        """The pair's row, {column name: value} in PAIR_TABLE's order (:func:`pair_row`)."""
        return pair_row(self.result, self.measured)

    @property
    def slip(self) -> int:
        return self.measured.slip

    @property
    def permeability(self) -> float:
        """kappa_c of the undrained branch [d^2]."""
        return self.measured.permeability

    @property
    def branch(self) -> str:
        """The undrained branch's folder name (perm_K)."""
        return self.measured.branch

    @property
    def regime(self) -> str:
        """The undrained branch's drainage regime (analysis.pairs.regime)."""
        return self.measured.regime



def _r2(fit) -> float:
    return float(fit.r2) if fit is not None else _NAN



def _verdict(fit) -> str:
    return fit.verdict if fit is not None else "none"


def _when(slip, attr: str, origin: float) -> float:
    """A slip's time in t0 since loading began (``origin``: the stored clock at that moment)."""
    return float(getattr(slip, attr)) - origin if slip is not None else _NAN


def deborah_during(time, deborah, slip) -> tuple[float, float]:
    """(De at the slip's onset, largest De from onset to end) of a branch's ``deborah`` series
    (Eq. 4: l half the layer thickness, u0 the largest deposited solid speed, D the mean
    diffusivity; see FluidGrid.observe); NaNs without a slip or a fluid."""
    if slip is None or deborah is None or len(deborah) == 0:
        return _NAN, _NAN
    i0 = int(np.searchsorted(time, slip.onset_time, side="left"))
    i1 = int(np.searchsorted(time, slip.end_time, side="right"))
    if i0 >= len(deborah):
        return _NAN, _NAN
    window = deborah[i0:max(i1, i0 + 1)]
    return float(deborah[i0]), float(np.nanmax(window)) if np.isfinite(window).any() else _NAN



def slip_deborah(time, deborah, wall_vx, slip, drained_peak: float) -> tuple[float, float]:
    """(De of the slip, l/D [t0/d]): De = l u0 / D (Eq. 4) with u0 the drained twin's peak wall
    speed ``drained_peak`` [v0] (grid-free, the same for every undrained branch of the slip) and
    l/D the undrained branch's, read off its ``deborah`` series where its wall is fastest during
    ``slip`` (De / |wall_vx| there). NaNs without a slip, a fluid or a moving wall."""
    if slip is None or deborah is None or len(deborah) == 0 or not np.isfinite(drained_peak):
        return _NAN, _NAN
    inside = (time >= slip.onset_time) & (time <= slip.end_time) & np.isfinite(deborah)
    if not inside.any():
        return _NAN, _NAN
    speed = np.where(inside, np.abs(wall_vx), -1.0)
    i = int(np.argmax(speed))
    if not speed[i] > 0:
        return _NAN, _NAN
    l_over_d = float(deborah[i] / speed[i])
    return l_over_d * abs(drained_peak), l_over_d


def dilation_before(time, thickness, onset: float) -> float:
    """Volumetric strain of the layer from the fork (the first sample) to ``onset`` [t0, stored
    clock]: (h(onset) - h(fork)) / h(fork), positive for dilation (2D, fixed width: the area
    strain is the thickness strain); NaN without an onset."""
    if thickness is None or len(thickness) == 0 or not np.isfinite(onset):
        return _NAN
    i = min(int(np.searchsorted(time, onset, side="left")), len(thickness) - 1)
    return float((thickness[i] - thickness[0]) / thickness[0])


def pressure_before(time, pressure_mean, onset: float) -> float:
    """The layer-mean pore pressure of largest magnitude from the fork to ``onset`` [E, signed]."""
    if pressure_mean is None or len(pressure_mean) == 0 or not np.isfinite(onset):
        return _NAN
    i = max(1, min(int(np.searchsorted(time, onset, side="right")), len(pressure_mean)))
    window = pressure_mean[:i][np.isfinite(pressure_mean[:i])]
    return float(window[np.argmax(np.abs(window))]) if window.size else _NAN


def rate_pressure(time, thickness, pressure_mean, onset: float, diffusion_time: float,
                  beta_phi: float) -> float:
    """The layer-mean pressure that the undrained branch's own strain rate sustains where the
    pressure drains faster than it builds, at the time of the peak (pressure_before):
    -(t_D / 3) eps_v' / (beta phi) [E] (the mean of the 1D diffusion equation with a uniform
    source, drained at both walls, in its quasi-steady limit), eps_v' = h'/h from a centred
    difference over max(t_D, 5 samples). NaN without an onset, a fluid or a thickness."""
    if pressure_mean is None or thickness is None or not (np.isfinite(onset) and diffusion_time > 0 and beta_phi > 0):
        return _NAN
    n = max(1, min(int(np.searchsorted(time, onset, side="right")), len(pressure_mean)))
    window = np.where(np.isfinite(pressure_mean[:n]), np.abs(pressure_mean[:n]), -1.0)
    i = int(np.argmax(window))
    if window[i] < 0:
        return _NAN
    half = max(0.5 * diffusion_time, 2.5 * float(np.median(np.diff(time))) if len(time) > 1 else 0.0)
    a = int(np.searchsorted(time, time[i] - half, side="left"))
    b = min(int(np.searchsorted(time, time[i] + half, side="right")) - 1, n - 1)
    if b <= a:
        return _NAN
    rate = (thickness[b] - thickness[a]) / (time[b] - time[a]) / thickness[i]
    return float(-diffusion_time / 3.0 * rate / beta_phi)


def pair_definition(info: RunInfo, main: str = "first") -> PairDefinition:
    """The pair definition with this run's detector thresholds."""
    return PairDefinition.for_run(info.slip_rule, main=main)



def _refuse_interrupted(info, fork_dir: Path):
    """An interrupted branch ends before its window: its pair is not classified."""
    if info.status == "interrupted":
        slip = ForkLayout(fork_dir).slip
        raise BranchInterruptedError(f"{info.run_dir} was interrupted before its end; its pair is not classified. Run "
                            f"`gouge restart {fork_dir.parent.parent} --slip {slip} --perm K` "
                            "(or `gouge study`) again to finish it")


def classify_fork(fork_dir: Path, main: str = "first") -> list[ForkPair]:
    """Classify every undrained branch of ``RUN/forks/slip_NNN`` against its drained branch.

    Uses :func:`~gouge_cli.analysis.pairs.classify_pair` with :func:`pair_definition` (the run's
    detector thresholds; ``main``: "first" or "largest"). Raises :class:`RunStillRunningError`
    when a branch is still running, :class:`AnalysisError` when one was interrupted, and
    :class:`NotARunError` when the drained branch is missing.
    """
    fork_dir = Path(fork_dir)
    drained_dir, undrained_dirs = fork_branches(fork_dir)
    if drained_dir is None:
        raise NotARunError(f"{fork_dir} has no drained/run.h5; run `gouge restart` for this slip again")
    pairs = []
    with RunReader(drained_dir) as d:
        info = d.info
        _refuse_interrupted(info, fork_dir)
        origin = d.time_offset()           # the branches carry the parent's loading clock on
        drained = wall_series(d)
        d_extra = {"time": drained.t, **d.series(["thickness"])}       # (time read once, with the wall)
        definition = pair_definition(info, main)
        for udir in undrained_dirs:
            with RunReader(udir) as u:
                _refuse_interrupted(u.info, fork_dir)
                undrained = wall_series(u)
                ds = {"time": undrained.t, "wall_vx": undrained.v_wall, "porosity": undrained.porosity,
                      **u.series(["deborah", "thickness", "pressure_mean"])}
                uinfo = u.info
            result = classify_pair(drained, undrained, info.V_s, info.k, info.m_b, info.sigma, definition)
            failure = next((f"{name} branch {st}" for name, st in (("drained", info.status), ("undrained", uinfo.status))
                            if st.startswith("failed")), "")
            if failure:     # a failed branch is no pair type: reported as failed, with its message
                result = replace(result, type=FAILED, base_type=FAILED, complex=False, undrained_event=FAILED,
                                 criteria={k: False for k in result.criteria}, note=failure)
            d_main, u_main = result.drained_slip, result.undrained_slip
            de_onset, de_max = deborah_during(ds["time"], ds["deborah"], u_main)
            de_slip = _NAN
            if u_main is not None and ds["deborah"] is not None:
                inside = (ds["time"] >= u_main.onset_time) & (ds["time"] <= u_main.end_time)
                de_slip = nan_mean(ds["deborah"][inside])
            de_mean = nan_mean(ds["deborah"])
            de = de_slip if math.isfinite(de_slip) else de_mean
            de_drained, l_over_d = slip_deborah(ds["time"], ds["deborah"], ds["wall_vx"], u_main,
                                                result.drained_peak_over_Vs * info.V_s)
            measured = PairMeasures(
                run=str(info.parent_dir),      # parent_run is stored relative to the branch
                slip=int(info.fork_slip) if info.fork_slip is not None else ForkLayout(fork_dir).slip,
                branch=udir.name,
                permeability=uinfo.permeability if uinfo.permeability is not None else _NAN,
                filter_width=uinfo.filter_width if uinfo.filter_width is not None else _NAN,
                cell_size=uinfo.grid_spacing if uinfo.grid_spacing is not None else _NAN,
                main=definition.main, origin=origin, failure=failure,
                deborah_mean=de_mean, deborah_slip=de_slip, regime=regime(de), deborah_onset=de_onset,
                deborah_max=de_max, deborah_drained=de_drained,
                mechanism=_mechanism(d_extra, ds, d_main, u_main, uinfo, l_over_d))
            pairs.append(ForkPair(result, measured, drained_dir, udir))
    return pairs



def _mechanism(drained: dict, undrained: dict, d_main, u_main, uinfo: RunInfo, l_over_d: float) -> "Mechanism":
    """The pair's test of the pressure equation (undrained limit P = -eps_v / (beta phi)):
    drained_dilation / undrained_dilation (eps_v of each branch from the fork to its onset [-]),
    pressure_peak (the undrained layer-mean pressure of largest magnitude before its onset [E]),
    undrained_pressure (|eps_v| / (beta phi) of the drained twin's strain, phi the porosity at the
    fork [E]), diffusion_time (t_D = l^2 / D [t0], l half the layer thickness) and onset_window
    (t_w, the fork to the undrained onset [t0]); pressure_from_rate (:func:`rate_pressure`: what
    the undrained branch's own strain rate at the peak sustains where the pressure drains quickly
    [E])."""
    fork_time = float(undrained["time"][0]) if undrained["time"] is not None and len(undrained["time"]) else _NAN
    d_onset = float(d_main.onset_time) if d_main is not None else _NAN
    u_onset = float(u_main.onset_time) if u_main is not None else _NAN
    eps_d = dilation_before(drained["time"], drained["thickness"], d_onset)
    eps_u = dilation_before(undrained["time"], undrained["thickness"], u_onset)
    fluid = (uinfo.config or {}).get("fluid") or {}
    beta = float(fluid.get("compressibility", _NAN))
    por = undrained["porosity"]
    phi = float(por[0]) if por is not None and len(por) else _NAN
    half = 0.5 * float(undrained["thickness"][0]) if undrained["thickness"] is not None else _NAN
    t_d = l_over_d * half if np.isfinite(l_over_d) else _NAN
    return Mechanism(
        drained_dilation=eps_d, undrained_dilation=eps_u,
        pressure_peak=pressure_before(undrained["time"], undrained["pressure_mean"], u_onset),
        undrained_pressure=abs(eps_d) / (beta * phi) if beta * phi > 0 else _NAN,
        diffusion_time=t_d, onset_window=u_onset - fork_time,
        pressure_from_rate=rate_pressure(undrained["time"], undrained["thickness"], undrained["pressure_mean"],
                                         u_onset, t_d, beta * phi))


def run_pairs(run_dir: Path, strict: bool = False, main: str = "first") -> tuple[list[ForkPair], list[str]]:
    """All pairs under ``RUN/forks`` (compared events chosen by ``main``). Returns (pairs, skipped):
    a fork that cannot be classified (still running, incomplete, damaged) is skipped with its reason, or
    raises when ``strict``."""
    pairs, skipped = [], []
    for fork in fork_dirs(run_dir):
        try:
            pairs.extend(classify_fork(fork, main))
        except (AnalysisError, DamagedFileError) as exc:      # a damaged branch is skipped, named
            if strict:
                raise
            skipped.append(Skipped(exc))
    return pairs, skipped


class Skipped(str):
    """Why a fork was skipped (its message); ``damaged``: False for a fork that is only unfinished
    (a branch still running or interrupted), which `gouge analyze` does not count as damaged."""

    def __new__(cls, exc: BaseException):
        text = super().__new__(cls, str(exc))
        text.damaged = not isinstance(exc, (RunStillRunningError, BranchInterruptedError))
        return text



def by_permeability(pairs: list[ForkPair]) -> dict[float, list[ForkPair]]:
    """The pairs grouped by kappa_c, in increasing order (pairs at different permeabilities are
    never pooled). ``pairs``: ForkPair, or anything with its ``permeability``, ``regime`` and
    ``result`` (analysis.campaign_table.RowPair, a pair read back from a table)."""
    groups: dict[float, list[ForkPair]] = {}
    for p in pairs:
        groups.setdefault(float(p.permeability), []).append(p)
    return dict(sorted(groups.items()))


def regime_counts(regimes) -> dict[str, int]:
    """{drainage regime: how many}, in the order the regimes first come."""
    counts: dict[str, int] = {}
    for name in regimes:
        counts[name] = counts.get(name, 0) + 1
    return counts


@dataclass(frozen=True)
class PermeabilityGroup:
    """The pairs of one kappa_c: their regimes and :class:`~gouge_cli.analysis.pairs.PairCounts`
    (JSON: ``{"permeability", "regimes", **pairs}``, :meth:`to_dict`)."""

    permeability: float = unit("d^2", "kappa_c of the undrained branches")
    regimes: dict = unit("-", "{drainage regime: pairs}")
    pairs: PairCounts = unit("-", "counts per type and ratio statistics")

    def to_dict(self) -> dict:
        return {"permeability": self.permeability, "regimes": dict(self.regimes), **plain(self.pairs)}


@dataclass(frozen=True)
class Campaign:
    """:func:`campaign`'s summary: the number of pairs and one :class:`PermeabilityGroup` per
    kappa_c, in increasing order (JSON: ``{"n", "per_permeability": [...]}``, :meth:`to_dict`)."""

    n: int = unit("-", "pairs")
    groups: tuple[PermeabilityGroup, ...] = unit("-", "one per permeability")

    def to_dict(self) -> dict:
        return {"n": self.n, "per_permeability": [g.to_dict() for g in self.groups]}


def campaign(pairs: list[ForkPair]) -> Campaign:
    """Counts per type and undrained/drained ratio statistics, one group per permeability (of one
    or more runs); never pooled over permeabilities."""
    return Campaign(len(pairs), tuple(
        PermeabilityGroup(perm, regime_counts(p.regime for p in members),
                          campaign_summary([p.result for p in members]))
        for perm, members in by_permeability(pairs).items()))
