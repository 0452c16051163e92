"""The drained/undrained findings against the Deborah number (thesis Eq. 4, Sec. 4.2-4.3, Table 3).

A *regime map* groups the pairs of a permeability sweep (one set of slips forked at every
kappa_c, so the comparison across De is paired) by permeability, per seed and pooled, and gives
for each group:

* the fractions of Type I, Type II and tie pairs (the pair definition's rule, with its tie band),
  of Type I by the sign of S_u - S_d alone (no tie band, as the thesis counted), and of complex
  (-C) pairs;
* the shares of pairs whose undrained branch is slower (peak velocity ratio < 1) and has the
  smaller stress drop (stress-drop ratio < 1);
* the medians of the peak-velocity, stress-drop and duration ratios;
* the median Deborah number of the slip (``deborah_drained``: Eq. 4 with u0 the drained twin's
  peak wall speed, the same for every undrained branch of the slip and free of the grid: the
  map's abscissa, :func:`abscissa`), and, as diagnostics, the undrained branches' own at the
  compared slip's onset and the largest during it (``deborah_onset`` / ``deborah_max``).

Two kinds of 95 % interval. The *per-pair* view treats every pair as independent: Wilson score
intervals for fractions (columns ``<key>_lo`` / ``<key>_hi``) and percentile-bootstrap intervals
over pairs for medians. The *seed-level* view, on the pooled row, treats the seed as the sampling
unit (``analysis.seedboot``: seeds resampled, then pairs within them; ``<key>_seed_lo`` /
``<key>_seed_hi``), beside the range of the per-seed fractions (``<key>_seed_min`` /
``<key>_seed_max``). Both use fixed generator seeds: the same table gives the same intervals.

:func:`delay_rows` asks whether "undrained slower" holds for slips at comparable stored stress
(the shares against the undrained branch's onset delay). :func:`thesis_point` places the thesis on
the same axes: its De from its own parameters and its Table 3 counts with their intervals.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

import numpy as np

from ..io.layout import perm_text
from .seedboot import seed_fraction, seed_median

__all__ = ["wilson", "bootstrap_median", "regime_rows", "thesis_point", "REGIME_COLUMNS",
           "RATIO_MEDIANS", "FRACTIONS", "ThesisPoint", "delay_rows", "onset_delay", "DELAY_COLUMNS",
           "DELAY_EDGES", "delay_points", "abscissa", "DEBORAH_COLUMNS", "THESIS_NORMAL_STRESS",
           "Estimate", "GroupCell", "pair_deborah", "group_cells", "COMPARED", "GROUP_COLUMNS"]

Z95 = 1.959963984540054
#: the Deborah numbers of a group (median, min, max of each): the slip's, then the undrained branches'
DEBORAH_COLUMNS = ("deborah_drained", "deborah_onset", "deborah_max", "deborah_mean")
RATIO_MEDIANS = ("peak_velocity_ratio", "stress_drop_ratio", "duration_ratio")
_NAN = float("nan")


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float, float]:
    """(k/n, lower, upper): the Wilson score interval of a binomial fraction; NaNs for n = 0."""
    if n <= 0:
        return _NAN, _NAN, _NAN
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return p, max(0.0, centre - half), min(1.0, centre + half)


def bootstrap_median(values, n_boot: int = 4000, level: float = 0.95,
                     seed: int = 20261126) -> tuple[float, float, float]:
    """(median, lower, upper): percentile-bootstrap interval of the median of the finite values."""
    x = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    if x.size == 0:
        return _NAN, _NAN, _NAN
    rng = np.random.default_rng(seed)
    meds = np.median(x[rng.integers(0, x.size, size=(n_boot, x.size))], axis=1)
    a = (1.0 - level) / 2.0
    return float(np.median(x)), float(np.quantile(meds, a)), float(np.quantile(meds, 1.0 - a))


def _num(row: dict, key: str) -> float:
    try:
        v = float(row.get(key, _NAN))
    except (TypeError, ValueError):
        return _NAN
    return v


def _flag(row: dict, key: str) -> bool:
    v = row.get(key, False)
    return v is True or str(v).strip().lower() in ("true", "1")


#: the fractions of a group: each a 0/1 outcome per classified pair (NaN: not counted)
FRACTIONS = ("type_I", "type_II", "tie", "type_I_sign", "complex", "slower", "smaller_drop")


def _classified(rows: list[dict]) -> list[dict]:
    return [r for r in rows if str(r.get("base_type")) in ("I", "II", "tie")]


def _below_one(v: float) -> float:
    return float(v < 1.0) if np.isfinite(v) else _NAN


def _outcomes(rows: list[dict]) -> dict[str, list[float]]:
    """Per classified pair: each fraction's 0/1 outcome (NaN where not counted: a ratio that is
    not finite) and each ratio's value."""
    cl = _classified(rows)
    out = {
        "type_I": [float(r["base_type"] == "I") for r in cl],
        "type_II": [float(r["base_type"] == "II") for r in cl],
        "tie": [float(r["base_type"] == "tie") for r in cl],
        "type_I_sign": [float(_num(r, "strength_difference") < 0) for r in cl],
        "complex": [float(_flag(r, "complex")) for r in cl],
        "slower": [_below_one(_num(r, "peak_velocity_ratio")) for r in cl],
        "smaller_drop": [_below_one(_num(r, "stress_drop_ratio")) for r in cl],
    }
    for col in RATIO_MEDIANS:
        out[col] = [_num(r, col) for r in cl]
    return out


def _group_stats(rows: list[dict]) -> dict:
    """Statistics of one group of pairs (one permeability, one seed or pooled): the per-pair view
    (Wilson intervals for fractions, pair bootstrap for medians)."""
    n = len(_classified(rows))
    out: dict = {"n_pairs": len(rows), "n_classified": n,
                 "n_none": len(rows) - n}
    oc = _outcomes(rows)
    for key in FRACTIONS:
        vals = [v for v in oc[key] if np.isfinite(v)]
        k = int(sum(vals))
        if key in ("slower", "smaller_drop"):
            out[f"n_{key}"], out[f"n_{key}_of"] = k, len(vals)
        else:
            out[f"n_{key}"] = k
        out[key], out[f"{key}_lo"], out[f"{key}_hi"] = wilson(k, len(vals))
    for col in RATIO_MEDIANS:
        m, lo, hi = bootstrap_median(oc[col])
        out[f"{col}_median"], out[f"{col}_lo"], out[f"{col}_hi"] = m, lo, hi
    for col in DEBORAH_COLUMNS:
        vals = [_num(r, col) for r in rows]
        vals = [v for v in vals if np.isfinite(v)]
        out[f"{col}_median"] = statistics.median(vals) if vals else _NAN
        out[f"{col}_min"] = min(vals) if vals else _NAN
        out[f"{col}_max"] = max(vals) if vals else _NAN
    return out


def seed_interval(by_seed: list[list[dict]], key: str) -> tuple[float, float]:
    """The seed-level 95 % interval (lo, hi) of fraction ``key`` (:data:`FRACTIONS`) over the
    classified pairs of groups of pair rows, one group per seed (``analysis.seedboot``: seeds
    resampled, then pairs within them). NaN for a single seed: there is no seed to resample."""
    if len(by_seed) < 2:
        return _NAN, _NAN
    _, lo, hi = seed_fraction([_outcomes(rows)[key] for rows in by_seed])
    return lo, hi


def _seed_stats(by_seed: list[list[dict]]) -> dict:
    """The seed-level view of a pooled group (one list of pair rows per seed): the number of
    seeds, for each fraction the range of the per-seed fractions and the 95 % seed-level interval
    (``analysis.seedboot``: seeds resampled, then pairs within them), and the seed-level
    intervals of the ratio medians. NaN for a single seed (there is no seed to resample)."""
    per_seed = [_outcomes(rows) for rows in by_seed]
    several = len(by_seed) > 1
    out: dict = {"n_seeds": len(by_seed)}
    for key in FRACTIONS:
        fr = [np.nanmean(oc[key]) for oc in per_seed if np.isfinite(oc[key]).any()]
        out[f"{key}_seed_min"] = min(fr) if fr else _NAN
        out[f"{key}_seed_max"] = max(fr) if fr else _NAN
        out[f"{key}_seed_lo"], out[f"{key}_seed_hi"] = seed_interval(by_seed, key)
    for col in RATIO_MEDIANS:
        _, lo, hi = seed_median([oc[col] for oc in per_seed]) if several else (_NAN, _NAN, _NAN)
        out[f"{col}_seed_lo"], out[f"{col}_seed_hi"] = lo, hi
    return out


def regime_rows(pair_rows: list[dict], seed_key: str = "seed") -> list[dict]:
    """One row per (permeability, seed) and per permeability pooled over seeds ("all").

    pair_rows: pair rows of a campaign table (``kind == 'pair'``) with permeability, base_type,
    complex, strength_difference, the three ratios, deborah_onset / deborah_max and, if present,
    ``transient`` (transient slips are left out) and the seed column. Permeabilities are never
    pooled with each other. The pooled row carries the seed-level view too (:func:`_seed_stats`);
    a seed's own row has NaN there.
    """
    rows = [r for r in pair_rows if not _flag(r, "transient")]
    perms = sorted({_num(r, "permeability") for r in rows})
    out = []
    for perm in perms:
        at = [r for r in rows if _num(r, "permeability") == perm]
        seeds = sorted({str(r.get(seed_key, "")) for r in at})
        by_seed = [[r for r in at if str(r.get(seed_key, "")) == s] for s in seeds]
        if len(seeds) > 1:
            for seed, group in zip(seeds, by_seed):
                out.append({"kappa_c": perm, "seed": seed, **_group_stats(group), **_seed_stats([group])})
        out.append({"kappa_c": perm, "seed": "all", **_group_stats(at), **_seed_stats(by_seed)})
    return out


def abscissa(row: dict) -> str:
    """The De column a regime row is placed at: the slip's (``deborah_drained``), or, for a table
    made before it existed, the undrained branches' largest (``deborah_max``)."""
    return "deborah_drained" if np.isfinite(_num(row, "deborah_drained_median")) else "deborah_max"


def pair_deborah(pair_rows: list[dict]) -> tuple[str, list[float]]:
    """(column, its finite values) of the measured De of a set of pairs, by :func:`abscissa`'s
    rule: the slip's (``deborah_drained``) where any pair has it, else ``deborah_max``."""
    for col in ("deborah_drained", "deborah_max"):
        vals = [v for v in (_num(r, col) for r in pair_rows) if np.isfinite(v)]
        if vals:
            return col, vals
    return "", []


#: columns of regime.csv (the keys of a group's statistics, after kappa_c and seed)
REGIME_COLUMNS = ["kappa_c", "seed", *_group_stats([]).keys(), *_seed_stats([]).keys()]


# --------------------------------------------------------------------------- groups on one set of axes

#: the findings compared between groups of pairs (thicknesses, stresses, couplings): four
#: fractions, then two medians of undrained / drained ratios
COMPARED = ("type_II", "complex", "slower", "smaller_drop", "peak_velocity_ratio", "stress_drop_ratio")


@dataclass(frozen=True)
class Estimate:
    """A pooled finding and its seed-level 95 % interval (NaN bounds for a single seed): here a
    fraction of pairs or a median ratio (seeds resampled, then pairs within them:
    ``analysis.seedboot``); a mean over seeds in ``analysis.recurrence`` (Student t)."""

    value: float
    seed_lo: float
    seed_hi: float


@dataclass(frozen=True)
class GroupCell:
    """One group of pairs (a layer thickness, a normal stress, a coupling: never pooled with
    another) at one permeability, pooled over its seeds: a row of groups.csv, a point of groups.png.

    kappa_c: the undrained branches' [d^2]. n_pairs: the non-transient pairs; n_classified: those
    with a slip in both branches (the fractions' denominator), of which n_type_II, n_complex,
    n_slower and n_smaller_drop. de_column: the pair column De is read from (:func:`abscissa`:
    ``deborah_drained``, the slip's, or ``deborah_max`` in tables made before it); de_median /
    de_min / de_max: over the cell's pairs (the figure's abscissa and its range); de_max_median:
    the undrained branches' largest De, kept beside it. The six findings (:data:`COMPARED`).
    """

    group: str
    kappa_c: float
    n_seeds: int
    n_pairs: int
    n_classified: int
    n_type_II: int
    n_complex: int
    n_slower: int
    n_smaller_drop: int
    de_column: str
    de_median: float
    de_min: float
    de_max: float
    de_max_median: float
    type_II: Estimate
    complex: Estimate
    slower: Estimate
    smaller_drop: Estimate
    peak_velocity_ratio: Estimate
    stress_drop_ratio: Estimate

    def finding(self, key: str) -> Estimate:
        """The :data:`COMPARED` finding ``key``."""
        if key not in COMPARED:
            raise KeyError(key)
        return getattr(self, key)

    def csv_row(self) -> dict:
        """The cell as one flat row (:data:`GROUP_COLUMNS`): each finding as key, key_seed_lo, key_seed_hi."""
        row = {k: getattr(self, k) for k in _GROUP_SCALARS}
        for key in COMPARED:
            e = self.finding(key)
            row[key], row[f"{key}_seed_lo"], row[f"{key}_seed_hi"] = e.value, e.seed_lo, e.seed_hi
        return row


_GROUP_SCALARS = ("group", "kappa_c", "n_seeds", "n_pairs", "n_classified", "n_type_II", "n_complex", "n_slower",
                  "n_smaller_drop", "de_column", "de_median", "de_min", "de_max", "de_max_median")
#: columns of groups.csv
GROUP_COLUMNS = [*_GROUP_SCALARS, *[f"{k}{s}" for k in COMPARED for s in ("", "_seed_lo", "_seed_hi")]]


def group_cells(group: str, rows: list[dict]) -> list[GroupCell]:
    """The pooled rows ("all") of :func:`regime_rows` of one group of pairs as :class:`GroupCell`,
    in order of kappa_c."""
    out = []
    for r in rows:
        if r["seed"] != "all":
            continue
        x = abscissa(r)

        def est(key: str) -> Estimate:
            value = r[f"{key}_median"] if key in RATIO_MEDIANS else r[key]
            return Estimate(value, r[f"{key}_seed_lo"], r[f"{key}_seed_hi"])

        out.append(GroupCell(group, r["kappa_c"], r["n_seeds"], r["n_pairs"], r["n_classified"], r["n_type_II"],
                             r["n_complex"], r["n_slower"], r["n_smaller_drop"], x, r[f"{x}_median"], r[f"{x}_min"],
                             r[f"{x}_max"], r["deborah_max_median"], *(est(k) for k in COMPARED)))
    return out


# --------------------------------------------------------------------------- slower, at equal footing

#: edges [t0] of the onset-delay bins: within about half a drained slip's duration (~16,000 t0 in
#: the study scene), within about 1.25 of it, and beyond
DELAY_EDGES = (7500.0, 20000.0)


def onset_delay(row: dict) -> float:
    """Onset of the undrained branch's compared slip less the drained one's [t0] (negative: the
    undrained branch slipped first)."""
    return _num(row, "undrained_onset") - _num(row, "drained_onset")


def delay_points(pair_rows: list[dict]) -> list[dict]:
    """The pairs :func:`delay_rows` counts (classified, not transient, with both onsets), each as
    kappa_c, seed, delay (:func:`onset_delay`), strength_difference and the two ratios."""
    return [{"kappa_c": _num(r, "permeability"), "seed": str(r.get("seed", "")), "delay": onset_delay(r),
             "strength_difference": _num(r, "strength_difference"),
             "peak_velocity_ratio": _num(r, "peak_velocity_ratio"), "stress_drop_ratio": _num(r, "stress_drop_ratio")}
            for r in _classified(pair_rows) if not _flag(r, "transient") and np.isfinite(onset_delay(r))]


def delay_rows(pair_rows: list[dict], edges=DELAY_EDGES, seed_key: str = "seed") -> list[dict]:
    """The thesis's "undrained slower, smaller drop" at equal footing: the slower and
    smaller-drop shares of the classified, non-transient pairs binned by |onset delay|
    (:func:`onset_delay`; bins [0, e1), [e1, e2), ..., [e_last, inf) t0), per permeability and
    pooled over permeabilities ("all": the same slips counted once per kappa_c), each with its
    Wilson (per-pair) and seed-level interval and the per-seed range; with the bin's median
    |delay| and median S_u - S_d (the stress the undrained branch stored beyond the drained one)."""
    rows = [r for r in _classified(pair_rows) if not _flag(r, "transient")
            and np.isfinite(onset_delay(r))]
    bounds = [0.0, *edges, math.inf]
    perms = sorted({_num(r, "permeability") for r in rows})
    out = []
    for perm in [*perms, "all"]:
        at = rows if perm == "all" else [r for r in rows if _num(r, "permeability") == perm]
        for lo_e, hi_e in zip(bounds[:-1], bounds[1:]):
            group = [r for r in at if lo_e <= abs(onset_delay(r)) < hi_e]
            seeds = sorted({str(r.get(seed_key, "")) for r in group})
            by_seed = [[r for r in group if str(r.get(seed_key, "")) == s] for s in seeds]
            row = {"kappa_c": perm, "delay_from": lo_e, "delay_to": hi_e, "n_pairs": len(group),
                   "delay_abs_median": statistics.median(abs(onset_delay(r)) for r in group) if group else _NAN,
                   "strength_difference_median": (statistics.median(_num(r, "strength_difference") for r in group)
                                                  if group else _NAN)}
            stats = _group_stats(group)
            seed_stats = _seed_stats(by_seed) if by_seed else {}
            for key in ("slower", "smaller_drop"):
                row[f"n_{key}"] = stats[f"n_{key}"]
                for suffix in ("", "_lo", "_hi"):
                    row[f"{key}{suffix}"] = stats[f"{key}{suffix}"]
                for suffix in ("_seed_lo", "_seed_hi", "_seed_min", "_seed_max"):
                    row[f"{key}{suffix}"] = seed_stats.get(f"{key}{suffix}", _NAN)
            row["n_seeds"] = len(seeds)
            out.append({c: row[c] for c in DELAY_COLUMNS})
    return out


#: columns of delay.csv
DELAY_COLUMNS = ["kappa_c", "delay_from", "delay_to", "n_pairs", "n_seeds", "delay_abs_median",
                 "strength_difference_median",
                 *[f"{p}{key}{s}" for key in ("slower", "smaller_drop")
                   for p, s in (("n_", ""), ("", ""), ("", "_lo"), ("", "_hi"), ("", "_seed_lo"),
                                ("", "_seed_hi"), ("", "_seed_min"), ("", "_seed_max"))]]


# --------------------------------------------------------------------------- the thesis on the map

# Loading velocities V_s [v0] of the 39 pairs of thesis Table 3, in its order, and their types.
THESIS_TABLE3 = (
    (2e-6, "II-C"), (2e-6, "I-C"), (2e-6, "I-C"), (5e-6, "II"), (5e-6, "II-C"), (5e-6, "I"),
    (5e-6, "II-C"), (5e-6, "II-C"), (5e-6, "I"), (9e-6, "II"), (9e-6, "II-C"), (9e-6, "II-C"),
    (1e-5, "II"), (1e-5, "II-C"), (1e-5, "I"), (8e-6, "II-C"), (8e-6, "I-C"), (8e-6, "II-C"),
    (8e-6, "II-C"), (8e-6, "II"), (8e-6, "I-C"), (7.5e-6, "II"), (7.5e-6, "II-C"), (7.5e-6, "II-C"),
    (1e-5, "II"), (1e-5, "II-C"), (1e-5, "I-C"), (1e-5, "II"), (1e-5, "II-C"), (1e-5, "II"),
    (1e-5, "I"), (3e-5, "II-C"), (3e-5, "II-C"), (3e-5, "II-C"), (3e-5, "II-C"), (3e-5, "II-C"),
    (3e-5, "II"), (3e-5, "II"), (1e-5, "II-C"),
)


@dataclass(frozen=True)
class ThesisPoint:
    """The thesis on the regime map: De (central, low, high) and its fractions with intervals."""

    deborah: float
    deborah_lo: float
    deborah_hi: float
    fractions: dict          # name -> (fraction, lower, upper)
    n_pairs: int
    assumptions: str
    kappa_c: float = 1e-5          # its permeability [d^2] (Table 3)
    normal_stress: float = 3e-4    # its sigma [E]: THESIS_NORMAL_STRESS

    def at(self, key: str) -> float | None:
        """The thesis's value of a phase-diagram axis (``permeability`` [d^2] or
        ``loading.normal_stress`` [E]); None for an axis it has no value on."""
        return {"permeability": self.kappa_c, "loading.normal_stress": self.normal_stress}.get(key)


#: the thesis's normal stress [E]: every run of its Table 3 (configs/thesis/*.yaml, loading.normal_stress)
THESIS_NORMAL_STRESS = 3e-4


def _diffusivity(kappa_c: float, phi: float, eta: float, beta: float) -> float:
    """D = kappa / (eta beta phi) with Carman-Kozeny kappa = kappa_c phi^3 / (1 - phi)^2 [d^2/t0]."""
    return kappa_c * phi**3 / (1.0 - phi) ** 2 / (eta * beta * phi)


def thesis_point(kappa_c: float = 1e-5, eta: float = 1.43e-7, beta: float = 36.0,
                 half_thickness: tuple[float, float, float] = (25.0, 12.5, 25.0),
                 peak_factor: tuple[float, float, float] = (7.53, 5.0, 15.0),
                 porosity: tuple[float, float, float] = (0.15, 0.20, 0.12)) -> ThesisPoint:
    """The thesis's Deborah number from its own parameters, comparable with ``deborah_max``.

    De = l u0 / D (Eq. 4) at the undrained slip's peak: l the distance from the layer's middle
    to a drained wall (its layer is ~50 d thick: 25 d; 12.5 d if the slip localises half way),
    u0 = f V_s the undrained peak wall speed (f = 7.53, its mean undrained peak over V_s in
    Sec. 4.2; 5 to 15 over its slips), V_s the median of Table 3 (low: its smallest, high: its
    largest), D from kappa_c = 1e-5 d^2 (Table 3) and Table 1's fluid (eta, beta in E t0 and 1/E)
    at porosity 0.15 (0.12-0.20, the range its permeabilities imply). Each tuple is (central,
    value giving the lowest De, value giving the highest De).
    """
    vs = sorted(v for v, _ in THESIS_TABLE3)
    v_med, v_lo, v_hi = statistics.median(vs), vs[0], vs[-1]
    de = [half_thickness[i] * peak_factor[i] * v / _diffusivity(kappa_c, porosity[i], eta, beta)
          for i, v in enumerate((v_med, v_lo, v_hi))]
    types = [t for _, t in THESIS_TABLE3]
    n = len(types)
    k_I = sum(t.startswith("I") and not t.startswith("II") for t in types)
    k_II = sum(t.startswith("II") for t in types)
    k_C = sum(t.endswith("-C") for t in types)
    fractions = {"type_I": wilson(k_I, n), "type_II": wilson(k_II, n), "tie": wilson(0, n),
                 "type_I_sign": wilson(k_I, n), "complex": wilson(k_C, n),
                 # "undrained systems always slip at a lower velocity" (Sec. 4.2): all 39
                 "slower": wilson(n, n)}
    text = ("De = l u0 / D at the undrained peak: l = 25 d (12.5-25), u0 = 7.53 V_s (5-15 V_s), "
            f"V_s = {v_med:g} v0 (Table 3 median; {v_lo:g}-{v_hi:g}), D at kappa_c = {perm_text(kappa_c)} d^2 "
            "and porosity 0.15 (0.12-0.20)")
    return ThesisPoint(de[0], de[1], de[2], fractions, n, text, kappa_c, THESIS_NORMAL_STRESS)
