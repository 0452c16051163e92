"""The seed-level (two-stage cluster) bootstrap against numbers derived by hand and against a
two-level binomial model whose true fraction is known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gouge_cli.analysis.regime import bootstrap_median, wilson
from gouge_cli.analysis.seedboot import cluster_bootstrap, seed_fraction, seed_median


def test_identical_seeds_give_the_per_pair_interval():
    # ten seeds with the same 3-of-10 outcome: resampling seeds changes nothing, and the pairs
    # within them resample to Binomial(100, 0.3) ones: sd sqrt(0.3 * 0.7 / 100) = 0.0458, width
    # 2 * 1.96 * 0.0458 = 0.180; Wilson(30, 100) is [0.219, 0.396], width 0.177
    seed = [1, 1, 1, 0, 0, 0, 0, 0, 0, 0]
    f, lo, hi = seed_fraction([seed] * 10)
    p, wlo, whi = wilson(30, 100)
    assert f == pytest.approx(p)
    assert (hi - lo) == pytest.approx(2 * 1.959964 * math.sqrt(0.21 / 100), rel=0.1)
    assert (hi - lo) == pytest.approx(whi - wlo, rel=0.1)
    assert lo == pytest.approx(wlo, abs=0.02) and hi == pytest.approx(whi, abs=0.02)


def test_seeds_that_differ_widen_the_interval_well_beyond_wilson():
    # seed fractions 0.1 / 0.5 / 0.9 of 10 pairs each: Wilson(15, 30) = [0.33, 0.67]; the
    # resampled seed sets alone put the pooled fraction anywhere from 0.1 to 0.9 (the set {0.1,
    # 0.1, 0.1} has probability 1/27), so the 95 % interval reaches below 0.2 and above 0.8
    groups = [[1] * k + [0] * (10 - k) for k in (1, 5, 9)]
    f, lo, hi = seed_fraction(groups)
    _, wlo, whi = wilson(15, 30)
    assert f == pytest.approx(0.5)
    assert lo < 0.2 and hi > 0.8
    assert (hi - lo) > 1.8 * (whi - wlo)


def test_all_or_nothing_and_empty():
    assert seed_fraction([[0] * 7, [0] * 13]) == (0.0, 0.0, 0.0)
    assert seed_fraction([[1] * 7, [1] * 3]) == (1.0, 1.0, 1.0)
    assert all(math.isnan(v) for v in seed_fraction([[], [float("nan")]]))
    assert all(math.isnan(v) for v in seed_median([]))


def test_pooled_fraction_weights_pairs_and_nans_are_not_counted():
    f, lo, hi = seed_fraction([[1, 0, float("nan")], [1, 1, 1, 1, 0, None]])
    assert f == pytest.approx(5 / 7)
    assert lo <= f <= hi


def test_deterministic_given_its_seed():
    groups = [[1, 0, 0, 1], [0, 0, 0], [1, 1, 0, 1, 1]]
    assert seed_fraction(groups, seed=4) == seed_fraction(groups, seed=4)
    rng = np.random.default_rng(1)
    x = [rng.normal(1.0, 0.2, n) for n in (7, 9, 5, 12)]
    assert seed_median(x, seed=2) == seed_median(x, seed=2)


def test_median_reduces_to_the_pair_bootstrap_for_identical_seeds_and_widens_when_they_differ():
    rng = np.random.default_rng(3)
    one = rng.normal(1.0, 0.2, 12)
    m, lo, hi = seed_median([one] * 8)
    bm, blo, bhi = bootstrap_median(np.tile(one, 8))
    assert m == pytest.approx(bm)
    assert (hi - lo) == pytest.approx(bhi - blo, rel=0.25)
    # seeds whose medians differ by 1.5 within-seed sd: the seed sets alone move the median by
    # up to +-0.3, while the 36 pooled pairs' bootstrap sees a spread of ~0.3 sd
    shifted = [one - 0.3, one, one + 0.3]
    m, lo, hi = seed_median(shifted)
    bm, blo, bhi = bootstrap_median(np.concatenate(shifted))
    assert (hi - lo) > 1.5 * (bhi - blo)
    assert lo < m - 0.2 and hi > m + 0.2


def test_cluster_bootstrap_of_the_mean_matches_the_two_stage_variance():
    # two-stage resampling of S equal clusters of n values: Var = s_b^2 (S-1)/S / S +
    # s_w^2 (n-1)/n / (S n), with s_b^2 the (population) variance of the cluster means and
    # s_w^2 the mean within-cluster (population) variance
    rng = np.random.default_rng(8)
    groups = [rng.normal(mu, 1.0, 10) for mu in rng.normal(0.0, 1.0, 6)]
    _, lo, hi = cluster_bootstrap(groups, np.mean, n_boot=20000)
    means = np.array([g.mean() for g in groups])
    var = means.var() / 6 + np.mean([g.var() for g in groups]) / 60
    assert (hi - lo) == pytest.approx(2 * 1.959964 * math.sqrt(var), rel=0.08)


def _coverage(n_seeds, rho, reps, mu=0.3, n_pairs=10, rng_seed=11):
    """Share of data sets from a two-level binomial model (seed fractions ~ Beta with mean mu and
    intra-seed correlation rho; n_pairs Bernoulli pairs per seed) whose interval holds mu:
    (seed-level, Wilson)."""
    rng = np.random.default_rng(rng_seed)
    hit_seed = hit_wilson = 0
    for r in range(reps):
        if rho > 0:
            ab = 1.0 / rho - 1.0
            p = rng.beta(mu * ab, (1.0 - mu) * ab, n_seeds)
        else:
            p = np.full(n_seeds, mu)
        groups = [(rng.random(n_pairs) < q).astype(float) for q in p]
        _, lo, hi = seed_fraction(groups, n_boot=1000, seed=r)
        _, wlo, whi = wilson(int(sum(g.sum() for g in groups)), n_seeds * n_pairs)
        hit_seed += lo <= mu <= hi
        hit_wilson += wlo <= mu <= whi
    return hit_seed / reps, hit_wilson / reps


@pytest.mark.parametrize("n_seeds,rho,least", [(10, 0.25, 0.92), (10, 0.0, 0.95), (3, 0.25, 0.82)])
def test_coverage_from_a_two_level_binomial_model(n_seeds, rho, least):
    """400 data sets (fixed generators): the standard error of a coverage c is sqrt(c (1 - c) / 400),
    0.011 at 0.95 and 0.017 at 0.86. Measured with these generators: 10 seeds, rho 0.25: 0.95
    (Wilson 0.70); 10 seeds, rho 0: 0.99 (Wilson 0.95; the second stage counts the pairs' noise
    twice, so it errs wide); 3 seeds, rho 0.25: 0.86 (Wilson 0.72); 3 seeds, rho 0.05: 0.95 (Wilson
    0.84). Each bound is the measured coverage less about 2.5 standard errors; where seeds differ,
    the same check fails the per-pair Wilson interval."""
    seed_cov, wilson_cov = _coverage(n_seeds, rho, 400)
    assert seed_cov >= least
    if rho > 0:
        assert wilson_cov < least                 # the check can fail: it fails the per-pair view


def test_seed_mean_is_the_student_t_interval():
    """One value per seed: mean 2, sample sd 1, and with 2 degrees of freedom the t quantile has a
    closed form, t_p = (2p - 1) sqrt(2 / (4 p (1 - p))) = 4.3027 at p = 0.975: half-width t / sqrt(3)
    (to the quantile's numerical precision); one seed has no interval; non-finite values are left out."""
    from gouge_cli.analysis.seedboot import seed_mean

    m, lo, hi = seed_mean([1.0, 2.0, float("nan"), 3.0])
    h = 0.95 * math.sqrt(2.0 / (4 * 0.975 * 0.025)) / math.sqrt(3.0)
    assert m == 2.0 and lo == pytest.approx(2.0 - h, rel=1e-9) and hi == pytest.approx(2.0 + h, rel=1e-9)
    assert np.isnan(seed_mean([5.0])[1]) and seed_mean([5.0])[0] == 5.0
