"""Intervals that count seeds: a two-stage (cluster) bootstrap over seeds, then pairs within them.

The pairs of one seed share a packing history, so they are not independent draws: a Wilson
interval over all pairs of a permeability (``analysis.regime.wilson``) is the *per-pair* view and
is too narrow when seeds differ. The seed-level view treats the seed as the sampling unit. Each
resample draws as many seeds as there are, with replacement, then, within each drawn seed, as many
pairs as it has, with replacement; the statistic is computed on the pooled resampled pairs (the
fraction of pairs, or the median of a ratio), and the interval is the percentile interval of the
resampled statistics. With one seed it reduces to the ordinary pair bootstrap; with seeds that
agree it approaches the per-pair interval; with seeds that disagree it widens with their spread.

A percentile bootstrap over few clusters under-covers (with three seeds the resampled seed sets
take only ten distinct values); ``tests/analysis/test_seedboot.py`` measures the coverage from a
two-level binomial model, and docs/regime_map.md states it. Deterministic: the same data and
``seed`` give the same interval.
"""

from __future__ import annotations

import numpy as np

__all__ = ["seed_fraction", "seed_median", "seed_mean", "cluster_bootstrap", "BOOT_SEED", "N_BOOT"]

BOOT_SEED = 20261127
N_BOOT = 4000
_NAN = float("nan")


def _clean(groups) -> list[np.ndarray]:
    out = []
    for g in groups:
        x = np.asarray([v for v in g if v is not None], dtype=float)
        x = x[np.isfinite(x)]
        if x.size:
            out.append(x)
    return out


def _interval(stats: np.ndarray, level: float) -> tuple[float, float]:
    a = (1.0 - level) / 2.0
    return float(np.quantile(stats, a)), float(np.quantile(stats, 1.0 - a))


def seed_fraction(groups, n_boot: int = N_BOOT, level: float = 0.95,
                  seed: int = BOOT_SEED) -> tuple[float, float, float]:
    """(pooled fraction, lower, upper) of 0/1 outcomes grouped by seed (one sequence per seed;
    NaN or None entries are not counted). The pooled fraction is (sum of ones) / (sum of pairs),
    as the per-pair view counts it. Resampling n_s pairs with replacement from a seed with k_s
    ones of n_s draws Binomial(n_s, k_s / n_s) ones, which is what is drawn here."""
    gs = _clean(groups)
    if not gs:
        return _NAN, _NAN, _NAN
    n = np.array([g.size for g in gs], dtype=np.int64)
    p = np.array([float(np.mean(g != 0)) for g in gs])
    estimate = float(np.sum(p * n) / np.sum(n))
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(gs), size=(n_boot, len(gs)))
    ones = rng.binomial(n[pick], p[pick])
    stats = ones.sum(axis=1) / n[pick].sum(axis=1)
    return (estimate, *_interval(stats, level))


def cluster_bootstrap(groups, statistic, n_boot: int = N_BOOT, level: float = 0.95,
                      seed: int = BOOT_SEED) -> tuple[float, float, float]:
    """(statistic of all pairs, lower, upper) for any statistic of the pooled pairs
    (``statistic(x) -> float`` on a 1-d array); non-finite values are left out first."""
    gs = _clean(groups)
    if not gs:
        return _NAN, _NAN, _NAN
    rng = np.random.default_rng(seed)
    s = len(gs)
    stats = np.empty(n_boot)
    picks = rng.integers(0, s, size=(n_boot, s))
    for b in range(n_boot):
        parts = [gs[i][rng.integers(0, gs[i].size, size=gs[i].size)] for i in picks[b]]
        stats[b] = statistic(np.concatenate(parts))
    return (float(statistic(np.concatenate(gs))), *_interval(stats, level))


def seed_median(groups, n_boot: int = N_BOOT, level: float = 0.95,
                seed: int = BOOT_SEED) -> tuple[float, float, float]:
    """(median of all pairs, lower, upper): :func:`cluster_bootstrap` of the median."""
    return cluster_bootstrap(groups, np.median, n_boot, level, seed)


def seed_mean(values, level: float = 0.95) -> tuple[float, float, float]:
    """(mean, lower, upper) of one value per seed: the Student-t interval (no bootstrap: each seed
    gives one number, e.g. a dilatancy coefficient); NaN bounds for one seed, all NaN for none."""
    from scipy import stats

    x = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    if x.size == 0:
        return _NAN, _NAN, _NAN
    m = float(x.mean())
    if x.size < 2:
        return m, _NAN, _NAN
    h = float(stats.t.ppf(0.5 + level / 2.0, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size))
    return m, m - h, m + h
