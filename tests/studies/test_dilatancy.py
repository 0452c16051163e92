"""Velocity steps (gouge_cli.studies.dilatancy): the step keeps the spring force continuous, an
undrained step's pore pressure follows its own dilation as the pressure equation's undrained limit
says, and the study keeps its finished points, skips them on a rerun and refuses other settings."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from gouge_cli.analysis.dilatancy import StepRun, cells
from gouge_cli.cli.main import app
from gouge_cli.config import build_config
from gouge_cli.driver.phases import guarded_run
from gouge_cli.driver.simulation import Simulation
from gouge_cli.errors import ConfigError
from gouge_cli.kernels import layout as L
from gouge_cli.studies import dilatancy as D

SCENE = {"name": "tiny-steps", "seed": 5, "packing": {"n_grains": 300, "width": 15},
         "loading": {"velocity": 4e-4}, "numerics": {"dt_safety": 0.3, "threads": 1}}


def _sliding(sigma=3e-4, perm=None) -> Simulation:
    cfg = D.scene(build_config(SCENE), SCENE["seed"], sigma, D.STIFF)
    sim = Simulation(cfg)
    guarded_run(sim, 10.0 / cfg.loading.velocity)          # 10 d of steady sliding
    return Simulation(D.wet(cfg, perm) if perm else cfg, arrays=sim.state.arrays())


def test_step_keeps_the_spring_force_and_drives_at_the_new_speed():
    sim = _sliding()
    v1 = sim.config.loading.velocity
    before = sim.spring_stretch()
    t_step, x_step = sim.state.clock[L.C_DRIVE_TIME], sim.state.wall[L.W_X]
    sim.set_loading_velocity(10 * v1)
    assert sim.spring_stretch() == pytest.approx(before, rel=1e-12, abs=1e-15)
    rows = guarded_run(sim, 20.0 / (10 * v1), interval=20.0)
    t, x = sim.state.clock[L.C_DRIVE_TIME], sim.state.wall[L.W_X]
    assert sim.spring_stretch() == pytest.approx(before + 10 * v1 * (t - t_step) - (x - x_step), rel=1e-9)
    # steady sliding at the new speed: the wall's mean velocity over the second half within 10 %
    half = [r["wall_vx"] for r in rows[len(rows) // 2:]]
    assert np.mean(half) == pytest.approx(10 * v1, rel=0.10)
    with pytest.raises(ValueError, match="must be positive"):
        sim.set_loading_velocity(0.0)


def test_faster_sliding_dilates_and_undrained_dilation_hardens():
    """One seed through the whole protocol (run-in, control, a x60 step drained and undrained at
    kappa_c 1e-9): the drained layer's steady porosity rises with the rate (the inertial number goes
    from ~1e-3 to ~0.08, where dense discs dilate by ~0.1 I), the undrained branch holds a suction
    (mean P < 0) and slides stronger than the drained one (dilatant hardening)."""
    run = D.run_steps(build_config(SCENE), SCENE["seed"], 3e-4, ratios=(60.0,), perm=1e-9, slip=12.0, run_in=10.0)
    drained, undrained = run.segment(60.0, True), run.segment(60.0, False)
    assert run.steady() and drained.velocity == pytest.approx(60 * SCENE["loading"]["velocity"], rel=0.1)
    assert drained.porosity - run.segment(1.0, True).porosity > 2e-3, run
    assert run.eps(60.0) > 5e-4
    assert 0.03 < run.slope(60.0) < 0.5, run.slope(60.0)     # b of phi = phi_c - b I: ~0.17 on the study layer
    assert undrained.pressure < 0 and run.measured_strengthening(60.0) > 0, run
    assert run.predicted_pressure(60.0) < 0 and run.predicted_strengthening(60.0) > 0


def test_study_keeps_finished_points_and_refuses_other_settings(tmp_path, monkeypatch):
    config = tmp_path / "tiny.yaml"
    config.write_text(json.dumps(SCENE))
    out = tmp_path / "steps"
    args = ["dilatancy", str(config), "--seeds", "5-6", "--ratio", "10", "--perm", "0", "--slip", "4",
            "--run-in", "4", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    kept = json.loads((out / "dilatancy_runs.json").read_text())
    runs = [StepRun.from_dict(r) for r in kept["runs"]]
    assert sorted(r.seed for r in runs) == [5, 6]
    assert all(len(r.segments) == 2 and all(s.drained for s in r.segments) for r in runs)
    lines = (out / "segments.csv").read_text().splitlines()
    assert len(lines) == 1 + 4
    (cell,) = cells(runs)
    assert cell.n_seeds == 2 and cell.eps[0] == pytest.approx(np.mean([r.eps(10.0) for r in runs]))
    assert f"{cell.eps[0]:.2e}" in (out / "summary.md").read_text()
    assert (out / "dilatancy.png").stat().st_size > 10_000

    def ran(*a, **k):
        raise AssertionError("a finished point ran again")

    monkeypatch.setattr(D, "run_steps", ran)
    again = CliRunner().invoke(app, args)
    assert again.exit_code == 0, again.output
    assert "0 of 2 (seed, sigma) points to run" in again.output
    (out / "summary.md").unlink()
    tables = CliRunner().invoke(app, [*args[:2], "--seeds", "5-7", *args[4:], "--tables"])
    assert tables.exit_code == 0 and "2 of 3 (seed, sigma) points kept" in tables.output, tables.output
    assert f"{cell.eps[0]:.2e}" in (out / "summary.md").read_text()
    with pytest.raises(ConfigError, match="another scene or settings"):
        D.run_study(build_config(SCENE), [5], [3e-4], out, ratios=(10.0,), perm=None, stiff=2e-2, slip=4, run_in=4)
