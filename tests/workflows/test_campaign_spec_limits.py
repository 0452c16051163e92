"""Campaign specs: an empty sweep (``sweep: {}``, ``grid: {}``, ``points: []``) is exit 2 naming the
key; a sweep is counted before it is expanded and refused above ``max_points`` (spec key, or
``--max-points``) with the count in the message. Nothing runs here: only the spec and --status."""

from __future__ import annotations

import time

import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT, SpecError
from gouge_cli.workflows.campaign_spec import MAX_POINTS, load_spec

SCENE = {"name": "tiny", "seed": 1, "packing": {"n_grains": 200, "width": 12}, "run": {"duration": 2000}}
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture
def folder(tmp_path, monkeypatch):
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(SCENE))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def spec_file(folder, **spec):
    path = folder / "spec.yaml"
    path.write_text(yaml.safe_dump({"name": "lim", "base": "tiny.yaml", **spec}, sort_keys=False))
    return path


@pytest.mark.parametrize("sweep, key", [
    ({}, "sweep: empty sweep"),
    ({"grid": {}}, "sweep.grid: empty"),
    ({"points": []}, "sweep.points: empty"),
    ({"grid": {}, "seeds": [1]}, "sweep.grid: empty"),
    ({"points": [{}]}, "sweep.points: sweep.points[0]: empty point"),
    (None, "sweep: required"),
])
def test_empty_sweep_is_refused_by_key(folder, sweep, key):
    spec = spec_file(folder) if sweep is None else spec_file(folder, sweep=sweep)
    for extra in ([], ["--status"]):
        result = gouge("campaign", spec, *extra)
        assert result.exit_code == EXIT_BAD_INPUT, result.output
        assert key in result.output and "Traceback" not in result.output
    assert not (folder / "campaigns").exists()


def test_seeds_alone_are_a_sweep(folder):
    spec = load_spec(spec_file(folder, sweep={"seeds": [1, 2, 3]}))
    assert spec.sweep.size() == 3


def test_huge_grid_is_counted_and_refused_before_expansion(folder):
    grid = {f"{section}.{key}": [1.0 + i for i in range(10)] for section, key in
            (("loading", "velocity"), ("loading", "normal_stress"), ("loading", "spring_constant"),
             ("material", "friction"), ("material", "damping"), ("packing", "width"))}
    spec = spec_file(folder, sweep={"grid": grid})
    t0 = time.perf_counter()
    result = gouge("campaign", spec)
    seconds = time.perf_counter() - t0
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert "1,000,000 points" in result.output and f"max_points = {MAX_POINTS:,}" in result.output
    assert "grid 10 x 10 x 10 x 10 x 10 x 10" in result.output and "--max-points" in result.output
    assert seconds < 10, f"refusing took {seconds:.1f} s: the sweep was expanded"
    assert not (folder / "campaigns").exists()


def test_limit_from_spec_and_option(folder):
    sweep = {"grid": {"loading.velocity": [1e-4, 2e-4, 3e-4], "loading.normal_stress": [3e-4, 4e-4]},
             "points": [{"loading.velocity": 5e-4}], "seeds": [1, 2]}
    spec = spec_file(folder, sweep=sweep, max_points=13)
    with pytest.raises(SpecError, match=r"14 points \(grid 3 x 2 \+ 1 listed points, each x 2 seeds\) exceed "
                                        r"max_points = 13"):
        load_spec(spec)
    assert load_spec(spec, max_points=14).sweep.size() == 14
    result = gouge("campaign", spec, "--status", "--max-points", "14")
    assert result.exit_code == 0, result.output
    assert "14 points" in result.output
    result = gouge("campaign", spec, "--status", "--max-points", "5")
    assert result.exit_code == EXIT_BAD_INPUT and "14 points" in result.output and "max_points = 5" in result.output
    result = gouge("campaign", spec_file(folder, sweep=sweep, max_points=0), "--status")
    assert result.exit_code == EXIT_BAD_INPUT and "max_points" in result.output
