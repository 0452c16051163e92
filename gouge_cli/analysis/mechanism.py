"""The mechanism behind Type I and Type II, tested against the pore-pressure equation.

In its undrained limit the Goren pressure equation (thesis Eqs. 14-16) gives P = -eps_v / (beta phi):
a layer that dilates (eps_v > 0) lowers its pore pressure, raises the effective normal stress and
so holds more shear stress. Two predictions follow, each checked per pair of a campaign table:

* **Sign.** The drained twin's volumetric strain from the fork to its onset (``drained_dilation``)
  predicts the type: dilation (dilatant hardening) gives Type II (S_u > S_d), compaction Type I.
  :func:`sign_outcome` scores a pair 1 where it does, 0 where not; ties and pairs without a
  strain are not counted.
* **Collapse.** The undrained branch's peak layer-mean pressure before its onset, divided by the
  undrained estimate |eps_v| / (beta phi) of the drained twin's strain (``pressure_peak`` /
  ``undrained_pressure``), is one function of t_D / t_w (``diffusion_time`` / ``onset_window``:
  the layer's diffusion time l^2 / D, l half its thickness, over the time the strain had to build
  up). For a layer drained at both walls and strained at a steady rate over t_w, the mean pressure
  solves the 1D diffusion equation with a uniform source: :func:`layer_response`, x/3 for small
  x = t_D / t_w (the pressure drains as it builds), 1 for large x (undrained). A strain that
  accelerates toward the onset leaves less time to drain and lies above the curve (at most 1).
  Scatter beyond a factor ~3 points at the coupling (the pressure is not the one of the mean
  strain) or at a strain localised in a band (the mean strain understates it).
* **Rate.** Where t_D << t_w the pressure drains as fast as it builds, and the pressure equation
  ties it to the strain rate of the moment: P = -(t_D / 3) eps_v' / (beta phi) (the same
  equation's quasi-steady limit), with eps_v' the undrained branch's own rate at the time of
  its peak (``pressure_from_rate``). :func:`rate_point` compares the two: the sign, and the
  ratio, which is 1 where the layer-mean strain rate is what drives the pressure.

:func:`mechanism_rows` gives both per permeability, per seed and pooled, with Wilson (per pair)
and seed-level (``analysis.seedboot``) intervals for the sign fraction.
"""

from __future__ import annotations

import math

import numpy as np

from .regime import _flag, _num, wilson
from .seedboot import seed_fraction

__all__ = ["layer_response", "sign_outcome", "collapse_point", "rate_point", "rate_agrees", "mechanism_rows",
           "MECHANISM_COLUMNS", "SCATTER_FACTOR"]

_NAN = float("nan")
#: the factor around :func:`layer_response` within which a pair counts as on the curve
SCATTER_FACTOR = 3.0


def layer_response(x, modes: int = 4000):
    """Mean pressure at t_w over its undrained value, for a layer of half thickness l drained at
    both walls (P = 0) with a uniform source steady over t_w, as a function of x = t_D / t_w
    (t_D = l^2 / D): sum over odd modes k = (2n+1) of 8 / (k pi)^2 u_k (1 - exp(-1 / u_k)),
    u_k = 4 x / (k pi)^2 (mode k's relaxation time over t_w); x/3 for small x, 1 for large x."""
    x = np.atleast_1d(np.asarray(x, dtype=float))
    k2 = (np.pi * (2 * np.arange(modes) + 1.0)) ** 2
    u = 4.0 * x[:, None] / k2[None, :]
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        y = np.sum(8.0 / k2 * u * -np.expm1(-1.0 / u), axis=1)
    return y if np.ndim(x) and x.size > 1 else float(y[0])


def sign_outcome(row: dict) -> float:
    """1.0 where the drained twin's pre-onset dilation predicts the pair's type (dilation: Type II,
    compaction: Type I), 0.0 where not, NaN where not counted (a tie, no type, no strain)."""
    eps = _num(row, "drained_dilation")
    kind = str(row.get("base_type"))
    if kind not in ("I", "II") or not math.isfinite(eps) or eps == 0.0:
        return _NAN
    return float((eps > 0) == (kind == "II"))


def collapse_point(row: dict) -> tuple[float, float]:
    """(t_D / t_w, peak |P| / (|eps_v| / (beta phi))) of a pair; NaNs where a quantity is missing."""
    x = _num(row, "diffusion_time") / _num(row, "onset_window")
    scale = _num(row, "undrained_pressure")
    y = abs(_num(row, "pressure_peak")) / scale if scale > 0 else _NAN
    return (x, y) if x > 0 and math.isfinite(x) and math.isfinite(y) and y > 0 else (_NAN, _NAN)


def rate_point(row: dict) -> tuple[float, float]:
    """(|P predicted from the strain rate|, |P measured|) [E] of a pair, and NaNs where missing;
    :func:`rate_agrees` says whether their signs agree."""
    pred, meas = _num(row, "pressure_from_rate"), _num(row, "pressure_peak")
    return (abs(pred), abs(meas)) if math.isfinite(pred) and math.isfinite(meas) and pred and meas else (_NAN, _NAN)


def rate_agrees(row: dict) -> bool:
    return _num(row, "pressure_from_rate") * _num(row, "pressure_peak") > 0


def _group(rows: list[dict]) -> dict:
    outcomes = [sign_outcome(r) for r in rows]
    counted = [v for v in outcomes if math.isfinite(v)]
    k = int(sum(counted))
    frac, lo, hi = wilson(k, len(counted))
    pts = [collapse_point(r) for r in rows]
    pts = [(x, y) for x, y in pts if math.isfinite(x)]
    ratio = np.array([y / float(layer_response(x)) for x, y in pts]) if pts else np.array([])
    log_r = np.log10(ratio) if ratio.size else ratio
    dil = [_num(r, "drained_dilation") for r in rows]
    return {"n_pairs": len(rows), "n_signed": len(counted), "n_predicted": k, "predicted": frac,
            "predicted_lo": lo, "predicted_hi": hi,
            "n_dilating": sum(1 for v in dil if math.isfinite(v) and v > 0),
            "n_compacting": sum(1 for v in dil if math.isfinite(v) and v < 0),
            "n_collapse": int(ratio.size),
            "collapse_ratio_median": float(np.median(ratio)) if ratio.size else _NAN,
            "collapse_within_factor": float(np.mean((ratio <= SCATTER_FACTOR) & (ratio >= 1 / SCATTER_FACTOR)))
            if ratio.size else _NAN,
            "collapse_log10_p10": float(np.quantile(log_r, 0.1)) if ratio.size else _NAN,
            "collapse_log10_p90": float(np.quantile(log_r, 0.9)) if ratio.size else _NAN,
            **_rate_stats(rows)}


def _rate_stats(rows: list[dict]) -> dict:
    """The rate test over a group: pairs with both pressures, those whose signs agree, the median
    measured / predicted and the share within SCATTER_FACTOR (same sign)."""
    pts = [(r, *rate_point(r)) for r in rows]
    pts = [(r, p, m) for r, p, m in pts if math.isfinite(p)]
    ratio = np.array([m / p for _, p, m in pts]) if pts else np.array([])
    agree = np.array([rate_agrees(r) for r, _, _ in pts], dtype=bool)
    within = (ratio <= SCATTER_FACTOR) & (ratio >= 1 / SCATTER_FACTOR) & agree if ratio.size else ratio
    return {"n_rate": int(ratio.size), "rate_sign_agrees": int(agree.sum()) if ratio.size else 0,
            "rate_ratio_median": float(np.median(ratio)) if ratio.size else _NAN,
            "rate_within_factor": float(np.mean(within)) if ratio.size else _NAN}


def mechanism_rows(pair_rows: list[dict], seed_key: str = "seed") -> list[dict]:
    """Per permeability: one row per seed (when several) and one pooled ("all") with the seed-level
    interval of the sign fraction (``predicted_seed_lo/hi``). Transient slips are left out, as in
    the regime map; pairs of every type enter the collapse, the classified ones the sign test."""
    rows = [r for r in pair_rows if not _flag(r, "transient")]
    out = []
    for perm in sorted({_num(r, "permeability") for r in rows}):
        at = [r for r in rows if _num(r, "permeability") == perm]
        seeds = sorted({str(r.get(seed_key, "")) for r in at})
        by_seed = [[r for r in at if str(r.get(seed_key, "")) == s] for s in seeds]
        if len(seeds) > 1:
            for seed, group in zip(seeds, by_seed):
                out.append({"kappa_c": perm, "seed": seed, **_group(group),
                            "predicted_seed_lo": _NAN, "predicted_seed_hi": _NAN})
        _, slo, shi = seed_fraction([[sign_outcome(r) for r in g] for g in by_seed]) if len(seeds) > 1 \
            else (_NAN, _NAN, _NAN)
        out.append({"kappa_c": perm, "seed": "all", **_group(at), "predicted_seed_lo": slo,
                    "predicted_seed_hi": shi})
    return out


MECHANISM_COLUMNS = ["kappa_c", "seed", *_group([]).keys(), "predicted_seed_lo", "predicted_seed_hi"]
