"""The study table and summary (thesis Table 3 / Appendix B, Sections 4.1-4.3): reads files only.

One row per drained/undrained pair (:data:`STUDY_COLUMNS`), built from the rows of
:func:`~gouge_cli.analysis.forkpairs.classify_fork` (the one pair definition) and the drained
slip's block-slider fit (Eq. 3). Transient slips (:func:`transient_slips`) are marked and left
out of every statistic of :func:`study_summary`, which is printed next to :data:`THESIS`.
"""

from __future__ import annotations

import csv
import math
import statistics
from dataclasses import dataclass

import numpy as np

from .blockslider import EQ3_PERIOD_FACTOR
from .catalog import fit_slip, fit_slip_notched, read_catalog
from .forkpairs import ForkPair, fired_criteria, regime_counts
from ..io.records import keys, plain, unit, units
from ..io.runreader import RunReader
from ..io.slipcatalog import SlipEntry

__all__ = ["StudyRow", "StudySummary", "StudyGroup", "Spread", "STUDY_COLUMNS", "STUDY_UNITS",
           "write_study_table", "THESIS", "TRANSIENT_TOL", "DURATION_TOL", "GOOD_R2",
           "transient_slips", "within_median", "study_rows", "study_summary", "study_summaries", "summary_lines"]

_NAN = float("nan")
TRANSIENT_TOL = 0.3     # a slip is steady when S and stress drop are within 30 % of the late medians
DURATION_TOL = 0.15     # drained durations "characteristic": within 15 % of their median
GOOD_R2 = 0.9           # a drained slip "fits Eq. 3" with R^2 above this (and passing the fit bar)

@dataclass(frozen=True)
class StudyRow:
    """One row of the study table (thesis Table 3 / Appendix B): one drained/undrained pair
    (:func:`study_rows`). Its CSV row is :func:`~gouge_cli.io.records.plain` of it, in field order."""

    slip: int = unit("-", "slip number the pair forks before")
    transient: bool = unit("-", "a transient slip (transient_slips), left out of every statistic")
    k: float = unit("E/d", "spring constant per length")
    sigma: float = unit("E", "normal stress")
    V: float = unit("v0", "loading velocity V_s")
    kappa_c: float = unit("d^2", "kappa_c of the undrained branch")
    deborah: float = unit("-", "mean De of the undrained branch over its compared slip")
    deborah_onset: float = unit("-", "De at the undrained onset")
    deborah_max: float = unit("-", "largest De over the undrained slip")
    regime: str = unit("-", "drainage regime (analysis.pairs.regime)")
    type: str = unit("-", "pair type (analysis.pairs), or failed")
    undrained_event: str = unit("-", "slip, slow slip below trigger, none (or failed)")
    S_d: float = unit("sigma", "static strength of the drained compared slip")
    S_u: float = unit("sigma", "static strength of the undrained compared slip")
    stress_drop_ratio: float = unit("-", "undrained / drained stress drop")
    peak_velocity_ratio: float = unit("-", "undrained / drained peak wall velocity")
    duration_ratio: float = unit("-", "undrained / drained slip duration")
    subevents: int = unit("-", "sub-events of the undrained compared slip")
    drained_duration: float = unit("t0", "duration of the drained slip in the parent run's catalog")
    drained_fit_r2: float = unit("-", "R^2 of its Eq. 3 fit")
    drained_fit_ok: bool = unit("-", "the fit passes the fit bar")
    drained_fit_verdict: str = unit("-", "holds, failed, inapplicable or none")
    drained_fit_r2_notched: float = unit("-", "R^2 refitted with the natural vibration notched (diagnostic)")
    m_eff_over_m_b: float = unit("-", "k (T_fit / pi)^2 / m_b (NaN when the fit fails the bar)")
    criteria: str = unit("-", "complexity criteria that fired, comma-separated")
    fit_reason: str = unit("-", "why the drained fit does not hold")
    note: str = unit("-", "one line for people")


STUDY_COLUMNS = keys(StudyRow)
STUDY_UNITS = units(StudyRow)


def write_study_table(path, rows: list[StudyRow]) -> None:
    """``study/table.csv``: one line per row, :data:`STUDY_COLUMNS`."""
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(STUDY_COLUMNS))
        w.writeheader()
        for row in rows:
            w.writerow(plain(row))


#: The thesis's study (Section 4.2-4.3, Table 3): 39 pairs at kappa_c = 1e-5.
THESIS = {"n": 39, "n_type_I": 9, "n_type_II": 30, "n_tie": 0, "n_complex": 25, "I-C": 5, "II-C": 20}


def transient_slips(catalog: list[SlipEntry], tol: float = TRANSIENT_TOL) -> set[int]:
    """Numbers of the transient slips of a run's catalog (io.slipcatalog.SlipEntry: number,
    static_strength, stress_drop).

    Rule: let S* and D* be the medians of static strength and stress drop over the second half
    of the catalog (slips ceil(n/2)+1 .. n; the run has reached repeated stick-slip by then).
    Slip 1 is always transient (it ends the first loading from rest); every later slip is
    transient until the first one with ``|S - S*| <= tol S*`` and ``|D - D*| <= tol D*``.
    """
    slips = sorted(catalog, key=lambda e: e.number)
    if not slips:
        return set()
    late = slips[len(slips) // 2:]
    s_ref = statistics.median(e.static_strength for e in late)
    d_ref = statistics.median(e.stress_drop for e in late)
    out = {slips[0].number}
    for e in slips[1:]:
        s, d = e.static_strength, e.stress_drop
        if abs(s - s_ref) <= tol * s_ref and abs(d - d_ref) <= tol * d_ref:
            break
        out.add(e.number)
    return out


def study_rows(run_dir, pairs: list[ForkPair], transient: set[int]) -> list[StudyRow]:
    """One row per pair (:class:`StudyRow`), in slip then permeability order.

    S_d, S_u: static strengths; ratios undrained / drained of the compared events; deborah: mean
    Deborah number of the undrained branch over its compared slip (deborah_onset / deborah_max: at
    its onset and the largest during it, forkpairs.deborah_during), regime: its drainage
    (analysis.pairs.regime); subevents: sub-events of the undrained event;
    drained_fit_*: Eq. 3 fit of the drained slip in the parent run's catalog (drained_fit_r2_notched:
    its R^2 refitted with the layer's natural vibration notched, a diagnostic,
    analysis.catalog.NotchedFit); m_eff_over_m_b: k (T_fit / pi)^2 / m_b of that fit (NaN when it
    fails the fit bar).
    """
    rows = []
    with RunReader(run_dir) as reader:
        info = reader.info
        catalog = {e.number: e for e in read_catalog(reader)}
        fits, notched = {}, {}
        for p in pairs:
            n = int(p.slip)
            if n not in fits and n in catalog:
                fits[n] = fit_slip(reader, catalog[n])
                refit = fit_slip_notched(reader, catalog[n], fits[n])
                notched[n] = refit.fit.r2 if refit is not None else _NAN
    for p in sorted(pairs, key=lambda q: (int(q.slip), q.permeability)):
        r, m, n = p.result, p.measured, int(p.slip)
        fit = fits.get(n)
        entry = catalog.get(n)
        rows.append(StudyRow(
            slip=n, transient=n in transient, k=info.k, sigma=info.sigma, V=info.V_s,
            kappa_c=m.permeability, deborah=m.deborah_slip, deborah_onset=m.deborah_onset,
            deborah_max=m.deborah_max, regime=m.regime, type=r.type, undrained_event=r.undrained_event,
            S_d=r.drained_strength, S_u=r.undrained_strength, stress_drop_ratio=r.stress_drop_ratio,
            peak_velocity_ratio=r.peak_velocity_ratio, duration_ratio=r.duration_ratio,
            subevents=int(r.n_subevents),
            drained_duration=entry.duration if entry is not None else _NAN,
            drained_fit_r2=fit.r2 if fit is not None else _NAN,
            drained_fit_ok=bool(fit is not None and fit.success),
            drained_fit_verdict=fit.verdict if fit is not None else "none",
            drained_fit_r2_notched=notched.get(n, _NAN),
            m_eff_over_m_b=fit.m_eff / info.m_b if (fit is not None and fit.success) else _NAN,
            criteria=fired_criteria(r),
            fit_reason=fit.verdict_reason if fit is not None else "",
            note=r.note,
        ))
    return rows


@dataclass(frozen=True)
class Spread:
    """Spread of a quantity over the finite values (all NaN and n 0 without one)."""

    n: int = unit("-", "finite values")
    mean: float = unit("-", "their mean")
    std: float = unit("-", "their standard deviation")
    cv: float = unit("-", "std / mean (NaN for a zero mean)")
    min: float = unit("-", "the smallest")
    max: float = unit("-", "the largest")


def _spread(values) -> Spread:
    a = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if a.size == 0:
        return Spread(0, _NAN, _NAN, _NAN, _NAN, _NAN)
    return Spread(int(a.size), float(a.mean()), float(a.std()), float(a.std() / a.mean()) if a.mean() else _NAN,
                  float(a.min()), float(a.max()))


def within_median(values, tol: float = DURATION_TOL) -> list[bool]:
    """For each value: within tol (a fraction) of the median of the finite ones (the study's
    "characteristic duration" test, thesis Sec. 4.1)."""
    finite = [v for v in values if math.isfinite(v)]
    med = statistics.median(finite) if finite else _NAN
    return [abs(v - med) <= tol * med for v in values]


@dataclass(frozen=True)
class StudySummary:
    """:func:`study_summary` of a set of study rows (the non-transient ones; drained slips counted
    once). Fractions are of the classified pairs (frac_*) or of the drained slips (drained_frac_*)."""

    n_rows: int = unit("-", "rows, transient ones included")
    n_transient_rows: int = unit("-", "rows of transient slips (left out of the rest)")
    n: int = unit("-", "pairs of steady slips")
    n_classified: int = unit("-", "of them with a type (not none or failed)")
    n_type_I: int = unit("-", "Type I, complex or not")
    n_type_II: int = unit("-", "Type II, complex or not")
    n_tie: int = unit("-", "ties")
    n_none: int = unit("-", "pairs whose undrained branch did not move")
    n_failed: int = unit("-", "pairs with a failed branch")
    n_complex: int = unit("-", "complex classified pairs")
    I_C: int = unit("-", "Type I-C", key="I-C")
    II_C: int = unit("-", "Type II-C", key="II-C")
    n_slow: int = unit("-", "classified pairs whose undrained event is a slow slip below the trigger")
    frac_slower: float = unit("-", "peak-velocity ratio < 1")
    frac_smaller_drop: float = unit("-", "stress-drop ratio < 1")
    n_drained: int = unit("-", "drained slips")
    drained_frac_fit_ok: float = unit("-", "passing the fit bar")
    drained_frac_eq3_holds: float = unit("-", "whose Eq. 3 fit holds (verdict holds)")
    drained_frac_r2_good: float = unit("-", "passing the bar with R^2 > GOOD_R2")
    drained_frac_r2_good_notched: float = unit("-", "the same with the natural vibration notched (diagnostic)")
    drained_frac_duration_within: float = unit("-", "duration within DURATION_TOL of the median")
    drained_duration_median: float = unit("t0", "median drained slip duration")
    m_eff_over_m_b: Spread = unit("-", "m_eff / m_b of the drained fits (in m_b)")


def study_summary(rows: list[StudyRow]) -> StudySummary:
    """Statistics over the non-transient rows (one per pair; drained slips counted once).

    counts: I, II, tie, none, complex (-C), slow; slower: fraction of classified pairs with
    peak-velocity ratio < 1; smaller_drop: stress-drop ratio < 1; drained: fraction of the
    study's drained slips passing the fit bar (and of those whose Eq. 3 fit holds, verdict "holds"), with R^2 > GOOD_R2 (and, a diagnostic, R^2 > GOOD_R2
    with the natural vibration notched), and with duration within DURATION_TOL of the median;
    m_eff (in m_b) mean, std, cv.
    """
    steady = [r for r in rows if not r.transient]
    classified = [r for r in steady if r.type not in ("none", "failed")]
    base = [r.type.replace("-C", "") for r in classified]
    drained = {r.slip: r for r in steady}.values()
    durations = [r.drained_duration for r in drained if math.isfinite(r.drained_duration)]
    med = statistics.median(durations) if durations else _NAN
    within = dict(zip((r.slip for r in drained), within_median([r.drained_duration for r in drained])))
    n_d = len(drained)

    def frac(rs, test):
        rs = list(rs)
        return sum(1 for r in rs if test(r)) / len(rs) if rs else _NAN

    return StudySummary(
        n_rows=len(rows), n_transient_rows=len(rows) - len(steady), n=len(steady),
        n_classified=len(classified),
        n_type_I=base.count("I"), n_type_II=base.count("II"), n_tie=base.count("tie"),
        n_none=sum(1 for r in steady if r.type == "none"),
        n_failed=sum(1 for r in steady if r.type == "failed"),
        n_complex=sum(1 for r in classified if r.type.endswith("-C")),
        I_C=sum(1 for r in classified if r.type == "I-C"),
        II_C=sum(1 for r in classified if r.type == "II-C"),
        n_slow=sum(1 for r in classified if r.undrained_event != "slip"),
        frac_slower=frac(classified, lambda r: r.peak_velocity_ratio < 1),
        frac_smaller_drop=frac(classified, lambda r: r.stress_drop_ratio < 1),
        n_drained=n_d,
        drained_frac_fit_ok=frac(drained, lambda r: r.drained_fit_ok),
        drained_frac_eq3_holds=frac(drained, lambda r: r.drained_fit_verdict == "holds"),
        drained_frac_r2_good=frac(drained, lambda r: r.drained_fit_ok and r.drained_fit_r2 > GOOD_R2),
        drained_frac_r2_good_notched=frac(drained, lambda r: r.drained_fit_ok and r.drained_fit_r2_notched > GOOD_R2),
        drained_frac_duration_within=frac(drained, lambda r: within[r.slip]),
        drained_duration_median=med,
        m_eff_over_m_b=_spread(r.m_eff_over_m_b for r in drained),
    )


@dataclass(frozen=True)
class StudyGroup:
    """The study rows of one kappa_c, summarised on their own (never pooled): JSON
    ``{"permeability", "regimes", **summary}`` (:meth:`to_dict`)."""

    permeability: float = unit("d^2", "kappa_c of the undrained branches")
    regimes: dict = unit("-", "{drainage regime: rows}")
    summary: StudySummary = unit("-", "study_summary of the rows")

    def to_dict(self) -> dict:
        return {"permeability": self.permeability, "regimes": dict(self.regimes), **plain(self.summary)}


def study_summaries(rows: list[StudyRow]) -> list[StudyGroup]:
    """:func:`study_summary` of each permeability's rows on its own (never pooled), in increasing
    kappa_c."""
    out = []
    for perm in sorted({float(r.kappa_c) for r in rows}):
        mine = [r for r in rows if float(r.kappa_c) == perm]
        out.append(StudyGroup(perm, regime_counts(r.regime for r in mine), study_summary(mine)))
    return out


def _pct(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{100 * x:.0f} %"


def summary_lines(s: StudySummary) -> list[tuple[str, str, str]]:
    """(quantity, this study, thesis) rows for printing side by side."""
    t = THESIS
    m = s.m_eff_over_m_b
    return [
        ("pairs (non-transient)", f"{s.n} ({s.n_transient_rows} transient left out)", str(t["n"])),
        ("Type I (of them -C)", f"{s.n_type_I} ({s.I_C})", f"{t['n_type_I']} ({t['I-C']})"),
        ("Type II (of them -C)", f"{s.n_type_II} ({s.II_C})", f"{t['n_type_II']} ({t['II-C']})"),
        ("tie", str(s.n_tie), str(t["n_tie"])),
        ("none (undrained did not move)", str(s.n_none), "–"),
        ("failed (a branch failed: see its note)", str(s.n_failed), "–"),
        ("complex (-C)", f"{s.n_complex} of {s.n_classified}", f"{t['n_complex']} of {t['n']}"),
        ("slow slip below trigger", str(s.n_slow), "– (not a category)"),
        ("undrained slower (peak v ratio < 1)", _pct(s.frac_slower), "not tabulated"),
        ("undrained smaller stress drop", _pct(s.frac_smaller_drop), "'in both Type I and II' (Figs. 9-10)"),
        ("drained slips passing the fit bar", _pct(s.drained_frac_fit_ok), "'good agreement' (Sec. 4.1)"),
        (f"  of them Eq. 3 holds (T/2 within {EQ3_PERIOD_FACTOR:g}x of π√(m_b/k))", _pct(s.drained_frac_eq3_holds),
         "'good agreement' (Sec. 4.1)"),
        (f"drained slips with R^2 > {GOOD_R2}", _pct(s.drained_frac_r2_good), "not tabulated"),
        ("  the same, natural vibration notched (diagnostic)", _pct(s.drained_frac_r2_good_notched),
         "fluctuations 'an artifact that Eq. 3 does not account for' (Secs. II, 4.1)"),
        (f"drained durations within {DURATION_TOL:.0%} of median",
         f"{_pct(s.drained_frac_duration_within)} (median {s.drained_duration_median:.4g} t0)",
         "constant (Sec. 4.1)"),
        ("m_eff / m_b, mean ± std (cv)",
         "–" if not m.n else f"{m.mean:.3g} ± {m.std:.2g} ({m.cv:.2f}, n {m.n})", "1 (Eq. 3)"),
    ]
