"""The drained/undrained findings against the Deborah number (thesis Eq. 4, Sec. 4.2-4.3, Table 3).

A *regime map* groups the pairs of a permeability sweep (one set of slips forked at every
kappa_c, so the comparison across De is paired) by permeability, per seed and pooled, and gives
for each group:

* the fractions of Type I, Type II and tie pairs (the pair definition's rule, with its tie band),
  of Type I by the sign of S_u - S_d alone (no tie band, as the thesis counted), and of complex
  (-C) pairs, each with a 95 % Wilson score interval;
* the shares of pairs whose undrained branch is slower (peak velocity ratio < 1) and has the
  smaller stress drop (stress-drop ratio < 1), with Wilson intervals;
* the medians of the peak-velocity, stress-drop and duration ratios with 95 % percentile-bootstrap
  intervals (a fixed generator seed: the same table gives the same intervals);
* the median Deborah number of the undrained branches at the compared slip's onset and the
  largest during it (columns ``deborah_onset`` / ``deborah_max`` of the pair table).

:func:`thesis_point` places the thesis on the same axes: its De from its own parameters and its
Table 3 counts with their intervals.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

import numpy as np

__all__ = ["wilson", "bootstrap_median", "regime_rows", "thesis_point", "REGIME_COLUMNS",
           "RATIO_MEDIANS", "ThesisPoint"]

Z95 = 1.959963984540054
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


def _group_stats(rows: list[dict]) -> dict:
    """Statistics of one group of pairs (one permeability, one seed or pooled)."""
    classified = [r for r in rows if str(r.get("base_type")) in ("I", "II", "tie")]
    n = len(classified)
    out: dict = {"n_pairs": len(rows), "n_classified": n,
                 "n_none": len(rows) - n}
    counts = {
        "type_I": sum(r["base_type"] == "I" for r in classified),
        "type_II": sum(r["base_type"] == "II" for r in classified),
        "tie": sum(r["base_type"] == "tie" for r in classified),
        "type_I_sign": sum(_num(r, "strength_difference") < 0 for r in classified),
        "complex": sum(_flag(r, "complex") for r in classified),
    }
    for key, k in counts.items():
        out[f"n_{key}"] = k
        out[key], out[f"{key}_lo"], out[f"{key}_hi"] = wilson(k, n)
    for key, col in (("slower", "peak_velocity_ratio"), ("smaller_drop", "stress_drop_ratio")):
        vals = [_num(r, col) for r in classified]
        vals = [v for v in vals if np.isfinite(v)]
        k = sum(v < 1.0 for v in vals)
        out[f"n_{key}"], out[f"n_{key}_of"] = k, len(vals)
        out[key], out[f"{key}_lo"], out[f"{key}_hi"] = wilson(k, len(vals))
    for col in RATIO_MEDIANS:
        m, lo, hi = bootstrap_median([_num(r, col) for r in classified])
        out[f"{col}_median"], out[f"{col}_lo"], out[f"{col}_hi"] = m, lo, hi
    for col in ("deborah_onset", "deborah_max", "deborah_mean"):
        vals = [_num(r, col) for r in rows]
        vals = [v for v in vals if np.isfinite(v)]
        out[f"{col}_median"] = statistics.median(vals) if vals else _NAN
        out[f"{col}_min"] = min(vals) if vals else _NAN
        out[f"{col}_max"] = max(vals) if vals else _NAN
    return out


def regime_rows(pair_rows: list[dict], seed_key: str = "seed") -> list[dict]:
    """One row per (permeability, seed) and per permeability pooled over seeds ("all").

    pair_rows: pair rows of a campaign table (``kind == 'pair'``) with permeability, base_type,
    complex, strength_difference, the three ratios, deborah_onset / deborah_max and, if present,
    ``transient`` (transient slips are left out) and the seed column. Permeabilities are never
    pooled with each other.
    """
    rows = [r for r in pair_rows if not _flag(r, "transient")]
    perms = sorted({_num(r, "permeability") for r in rows})
    out = []
    for perm in perms:
        at = [r for r in rows if _num(r, "permeability") == perm]
        seeds = sorted({str(r.get(seed_key, "")) for r in at})
        groups = [(s, [r for r in at if str(r.get(seed_key, "")) == s]) for s in seeds] if len(seeds) > 1 else []
        groups.append(("all", at))
        for seed, group in groups:
            out.append({"kappa_c": perm, "seed": seed, **_group_stats(group)})
    return out


#: columns of regime.csv (the keys of a group's statistics, after kappa_c and seed)
REGIME_COLUMNS = ["kappa_c", "seed", *_group_stats([]).keys()]


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
            f"V_s = {v_med:g} v0 (Table 3 median; {v_lo:g}-{v_hi:g}), D at kappa_c = {kappa_c:g} d^2 "
            "and porosity 0.15 (0.12-0.20)")
    return ThesisPoint(de[0], de[1], de[2], fractions, n, text)
