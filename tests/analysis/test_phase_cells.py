"""Phase-diagram cells carry seed-level intervals: the seed is the sampling unit (issue 63)."""

from __future__ import annotations

import math

import pytest

from gouge_cli.analysis.campaign_table import PHASE_COLUMNS, phase_cells


def _rows(seed: int, n: int, n_complex: int, n_type_II: int, sigma: float = 3e-4, perm: float = 1e-5) -> list[dict]:
    return [{"seed": seed, "permeability": perm, "loading.normal_stress": sigma, "complex": i < n_complex,
             "base_type": "II" if i < n_type_II else "I"} for i in range(n)]


def test_seeds_that_disagree_widen_the_interval_to_their_spread():
    """Seed 1 all -C, seed 2 none: the pooled fraction is 1/2 and, resampling seeds, a quarter of
    the draws take seed 1 twice (fraction 1) and a quarter seed 2 twice (0): the 95 % interval is
    [0, 1]. Seeds that agree (each 5 of 10) give the per-pair spread, well inside it."""
    split = phase_cells(_rows(1, 10, 10, 0) + _rows(2, 10, 0, 0), "permeability", "loading.normal_stress")
    agree = phase_cells(_rows(1, 10, 5, 0) + _rows(2, 10, 5, 0), "permeability", "loading.normal_stress")
    (c,), (a,) = split, agree
    assert c["n_seeds"] == 2 and c["n_pairs"] == 20 and c["frac_complex"] == pytest.approx(0.5)
    assert c["frac_complex_lo"] == 0.0 and c["frac_complex_hi"] == 1.0
    assert a["frac_complex"] == pytest.approx(0.5)
    # two seeds of 10 Bernoulli(1/2) pairs: sd of the pooled fraction sqrt(0.25/20) = 0.11
    assert 0.2 < a["frac_complex_lo"] < 0.4 and 0.6 < a["frac_complex_hi"] < 0.8
    assert a["frac_type_II"] == 0.0 and a["frac_type_II_lo"] == a["frac_type_II_hi"] == 0.0


def test_cells_over_two_axes_are_not_pooled_and_empty_cells_are_nan():
    rows = (_rows(1, 8, 2, 8) + _rows(2, 8, 4, 6) + _rows(1, 6, 6, 0, sigma=1e-3)
            + [{"seed": 3, "permeability": 1e-5, "loading.normal_stress": 1e-4, "complex": False, "base_type": "none"}])
    cells = {c["y"]: c for c in phase_cells(rows, "permeability", "loading.normal_stress")}
    assert set(cells) == {1e-4, 3e-4, 1e-3} and all(set(PHASE_COLUMNS) <= set(c) for c in cells.values())
    assert cells[3e-4]["n_seeds"] == 2 and cells[3e-4]["frac_type_II"] == pytest.approx(14 / 16)
    assert cells[3e-4]["frac_type_II_lo"] <= 14 / 16 <= cells[3e-4]["frac_type_II_hi"]
    assert cells[1e-3]["n_seeds"] == 1 and cells[1e-3]["frac_complex"] == 1.0
    empty = cells[1e-4]
    assert empty["n_pairs"] == 0 and empty["n_unclassified"] == 1 and empty["n_seeds"] == 0
    assert all(math.isnan(empty[k]) for k in ("frac_complex", "frac_complex_lo", "frac_type_II_hi"))
