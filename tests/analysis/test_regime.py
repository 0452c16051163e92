"""The regime map's statistics (analysis.regime) against independent references, and its figure."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binomtest

from gouge_cli.analysis.regime import (REGIME_COLUMNS, THESIS_TABLE3, bootstrap_median, regime_rows,
                                       thesis_point, wilson)


@pytest.mark.parametrize("k,n", [(9, 39), (0, 39), (39, 39), (2, 20), (11, 20), (1, 3)])
def test_wilson_matches_scipy(k, n):
    p, lo, hi = wilson(k, n)
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert p == pytest.approx(k / n)
    assert lo == pytest.approx(ci.low, abs=1e-12)
    assert hi == pytest.approx(ci.high, abs=1e-12)


def test_wilson_of_nothing_is_nan():
    assert all(math.isnan(v) for v in wilson(0, 0))


def test_bootstrap_median_interval_has_the_asymptotic_width_and_is_reproducible():
    rng = np.random.default_rng(5)
    x = rng.normal(1.0, 0.2, 400)
    m, lo, hi = bootstrap_median(x)
    assert m == pytest.approx(float(np.median(x)))
    assert lo < m < hi
    # asymptotic s.e. of a normal sample's median: sqrt(pi/2) sigma / sqrt(n)
    width = 2 * 1.96 * math.sqrt(math.pi / 2) * 0.2 / math.sqrt(400)
    assert (hi - lo) == pytest.approx(width, rel=0.3)
    assert bootstrap_median(x) == (m, lo, hi)
    assert all(math.isnan(v) for v in bootstrap_median([float("nan")]))


def _pair(perm, seed, base, sdiff, pvr, sdr, de, complex_=False, transient=False):
    return {"kind": "pair", "permeability": perm, "seed": seed, "base_type": base, "complex": complex_,
            "strength_difference": sdiff, "peak_velocity_ratio": pvr, "stress_drop_ratio": sdr,
            "duration_ratio": 1.0, "deborah_onset": de / 10, "deborah_max": de, "deborah_mean": de / 20,
            "transient": transient}


def test_regime_rows_never_pool_permeabilities_and_leave_out_transients():
    pairs = [
        _pair(1e-5, 3, "I", -0.01, 0.8, 0.9, 0.03), _pair(1e-5, 3, "II", 0.02, 1.2, 1.1, 0.02, True),
        _pair(1e-5, 7, "tie", -0.0005, 0.9, 1.3, 0.04), _pair(1e-5, 7, "none", float("nan"), float("nan"),
                                                             float("nan"), 0.05),
        _pair(1e-6, 3, "I", -0.02, 0.5, 0.5, 0.3, True), _pair(1e-6, 7, "I", -0.03, 0.7, 0.6, 0.4),
        _pair(1e-6, 7, "II", 0.01, 1.1, 0.8, 0.5, transient=True),      # left out
    ]
    rows = regime_rows(pairs)
    assert list(rows[0]) == REGIME_COLUMNS
    by = {(r["kappa_c"], r["seed"]): r for r in rows}
    assert set(by) == {(1e-6, "3"), (1e-6, "7"), (1e-6, "all"), (1e-5, "3"), (1e-5, "7"), (1e-5, "all")}
    a = by[(1e-5, "all")]
    assert (a["n_pairs"], a["n_classified"], a["n_none"]) == (4, 3, 1)
    assert (a["n_type_I"], a["n_type_II"], a["n_tie"]) == (1, 1, 1)
    assert a["n_type_I_sign"] == 2                         # the tie has S_u < S_d
    assert (a["n_slower"], a["n_slower_of"]) == (2, 3)
    assert (a["n_smaller_drop"], a["n_smaller_drop_of"]) == (1, 3)
    assert a["n_complex"] == 1
    assert a["type_I_lo"] == pytest.approx(wilson(1, 3)[1])
    assert a["deborah_max_median"] == pytest.approx(0.035)
    b = by[(1e-6, "all")]
    assert (b["n_pairs"], b["n_type_I"], b["n_type_II"]) == (2, 2, 0)
    assert b["peak_velocity_ratio_median"] == pytest.approx(0.6)


def test_thesis_point_counts_and_deborah():
    t = thesis_point()
    assert len(THESIS_TABLE3) == t.n_pairs == 39
    assert t.fractions["type_I"][0] == pytest.approx(9 / 39)
    assert t.fractions["type_II"][0] == pytest.approx(30 / 39)
    assert t.fractions["complex"][0] == pytest.approx(25 / 39)
    # by hand: D = 1e-5 * 0.15^2 / 0.85^2 / (1.43e-7 * 36); De = 25 * 7.53 * 9e-6 / D (Table 3 median V_s)
    d = 1e-5 * 0.15**2 / 0.85**2 / (1.43e-7 * 36)
    assert t.deborah == pytest.approx(25 * 7.53 * 9e-6 / d, rel=1e-12)
    assert t.deborah_lo < t.deborah < t.deborah_hi


def test_regime_figure_is_written(tmp_path):
    from gouge_cli.plots.regime import regime_figure

    pairs = [_pair(k, s, b, -0.01 if b == "I" else 0.01, 0.9, 1.1, de)
             for k, de in ((1e-5, 0.03), (1e-6, 0.3)) for s in (3, 7) for b in ("I", "II", "II")]
    path = regime_figure(regime_rows(pairs), thesis_point(), tmp_path / "regime.png", "test")
    assert path.stat().st_size > 10_000


def test_pooled_rows_carry_the_seed_level_view_and_seed_rows_do_not():
    from gouge_cli.analysis.seedboot import seed_fraction, seed_median

    # seed 3: 1 Type I of 4, seed 7: 3 of 4 (the per-seed fractions 0.25 and 0.75)
    pairs = [_pair(1e-5, s, b, -0.01 if b == "I" else 0.01, v, 1.0, 0.1)
             for s in (3, 7) for b, v in zip(("I", "II", "II", "II") if s == 3
                                                                        else ("I", "I", "I", "II"),
                                                                        (0.8, 0.9, 1.1, 1.2))]
    by = {r["seed"]: r for r in regime_rows(pairs)}
    a = by["all"]
    assert a["n_seeds"] == 2 and by["3"]["n_seeds"] == 1
    assert (a["type_I_seed_min"], a["type_I_seed_max"]) == (0.25, 0.75)
    assert (by["3"]["type_I_seed_min"], by["7"]["type_I_seed_max"]) == (0.25, 0.75)
    assert (a["type_I_seed_lo"], a["type_I_seed_hi"]) == seed_fraction([[1, 0, 0, 0], [1, 1, 1, 0]])[1:]
    assert (a["peak_velocity_ratio_seed_lo"], a["peak_velocity_ratio_seed_hi"]) == \
        seed_median([[0.8, 0.9, 1.1, 1.2]] * 2)[1:]
    assert a["type_I_seed_lo"] <= a["type_I"] <= a["type_I_seed_hi"]
    assert math.isnan(by["3"]["type_I_seed_lo"]) and math.isnan(by["7"]["slower_seed_hi"])


def test_delay_rows_bin_by_onset_delay_per_permeability_and_pooled():
    from gouge_cli.analysis.regime import DELAY_COLUMNS, DELAY_EDGES, delay_rows, onset_delay

    def p(perm, seed, delay, pvr, sdr, transient=False):
        r = _pair(perm, seed, "II" if delay > 0 else "I", 1e-6 * delay, pvr, sdr, 0.1, transient=transient)
        r.update(drained_onset=1.0e5, undrained_onset=1.0e5 + delay)
        return r

    pairs = [p(1e-5, 3, -2000, 0.8, 0.9), p(1e-5, 7, 5000, 0.9, 1.1), p(1e-5, 7, 30000, 1.4, 2.0),
             p(1e-6, 3, 10000, 0.7, 0.6), p(1e-6, 3, 40000, 1.2, 0.9), p(1e-6, 7, 100, 1.1, 1.2, True)]
    assert onset_delay(pairs[0]) == -2000
    rows = delay_rows(pairs)
    assert all(list(r) == DELAY_COLUMNS for r in rows)
    assert len(rows) == 3 * (len(DELAY_EDGES) + 1)
    by = {(r["kappa_c"], r["delay_from"]): r for r in rows}
    near = by[(1e-5, 0.0)]                       # |-2000| and 5000: both slower, one smaller drop
    assert (near["n_pairs"], near["n_slower"], near["n_smaller_drop"], near["n_seeds"]) == (2, 2, 1, 2)
    assert near["delay_abs_median"] == 3500
    far = by[(1e-5, DELAY_EDGES[1])]
    assert (far["n_pairs"], far["n_slower"], far["slower"]) == (1, 0, 0.0)
    pooled = by[("all", 0.0)]                    # the transient pair is left out
    assert pooled["n_pairs"] == 2
    assert by[("all", DELAY_EDGES[0])]["n_pairs"] == 1 and by[("all", DELAY_EDGES[1])]["n_pairs"] == 2
    assert by[(1e-6, 0.0)]["n_pairs"] == 0 and math.isnan(by[(1e-6, 0.0)]["slower"])
