"""The verdict's campaign specs (issue 47) parse, expand to the points they promise, and keep the
relations their comments state (checked from the spec files, not restated)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gouge_cli.model.packing import packing_layout
from gouge_cli.workflows.campaign_spec import expand, load_spec, phase_axes

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _load(name):
    path = EXAMPLES / name
    spec = load_spec(path)
    return spec, expand(spec, path)


def test_seeds_spec_has_ten_seeds_or_more_at_the_two_verdict_points():
    spec, points = _load("verdict_seeds.yaml")
    assert spec.action == "study"
    assert spec.study.permeabilities == [3.0e-6, 1.0e-5]
    assert len(points) == len(spec.sweep.seeds) == 12 >= 10
    assert {3, 7, 11} <= set(spec.sweep.seeds)                      # the regime map's seeds
    assert {p.config.seed for p in points} == set(spec.sweep.seeds)
    assert all(p.config.packing.n_grains == 2000 and p.config.run.duration == 2.5e6 for p in points)
    assert phase_axes(spec) == ("permeability", "seed")


def _free(config):
    width, _, n_free, _ = packing_layout(config)
    return width, n_free


def test_thickness_spec_scales_the_free_grains_keeps_the_width_and_matches_de():
    spec, points = _load("verdict_thickness.yaml")
    thin_spec, thin = _load("verdict_seeds.yaml")
    assert len(points) == 2 * 5 and len(spec.sweep.seeds) >= 5
    width0, free0 = _free(thin[0].config)
    ratios = set()
    for p in points:
        width, free = _free(p.config)
        assert width == width0
        ratios.add(free / free0)
        assert p.config.loading == thin[0].config.loading            # same sigma, spring, V_s, wall mass
    assert ratios == {2.0, 4.0}
    # matched De at equal u0 and porosity: kappa_c proportional to the half thickness
    perms = spec.study.permeabilities
    for ratio in (2, 4):
        for k_thin in thin_spec.study.permeabilities:
            assert any(math.isclose(k, ratio * k_thin, rel_tol=1e-12) for k in perms), (ratio, k_thin)
    assert phase_axes(spec) == ("permeability", "packing.n_grains")


def test_sigma_spec_spans_a_decade_around_the_study_scene_with_four_seeds():
    spec, points = _load("verdict_sigma.yaml")
    assert len(points) == 3 * len(spec.sweep.seeds) and len(spec.sweep.seeds) >= 4
    sigmas = sorted({p.config.loading.normal_stress for p in points})
    assert len(sigmas) == 3
    assert sigmas[-1] / sigmas[0] == pytest.approx(10.0)
    assert math.sqrt(sigmas[0] * sigmas[-1]) == pytest.approx(3.0e-4, rel=0.06)
    assert 3.0e-4 in sigmas
    # the run length grows with sigma (the loading time between slips does)
    by_sigma = {p.config.loading.normal_stress: p.config.run.duration for p in points}
    assert [by_sigma[s] for s in sigmas] == sorted(by_sigma[s] for s in sigmas)
    assert {1.0e-5, 3.0e-6, 1.0e-6} <= set(spec.study.permeabilities) and spec.study.skip_transient
    assert phase_axes(spec) == ("permeability", "loading.normal_stress")


def test_a_point_name_with_an_exponent_is_a_valid_run_name():
    from gouge_cli.workflows.campaign_spec import point_name

    name = point_name({"run.duration": 2.5e6, "loading.normal_stress": 1.0e-4})
    assert "+" not in name and "2.5e06" in name
