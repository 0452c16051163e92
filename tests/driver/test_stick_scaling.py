"""Stick scaling's pieces on small scenes: inertia and step consistent with lambda and exactly undone
at lambda = 1, the inertial-number guard, the wet-run refusal, and the ladder's statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.config import build_config
from gouge_cli.errors import ConfigError
from gouge_cli.kernels import layout as K
from gouge_cli.studies.scaling_ladder import summarize
from gouge_cli.driver.simulation import Simulation
from gouge_cli.driver.stick_scaling import StickScaling, set_inertia
from gouge_cli.model.timestep import choose_dt

SMALL = {"packing": {"n_grains": 60, "width": 8}, "seed": 3,
         "loading": {"spring_constant": 2e-4, "velocity": 4e-5},
         "compaction": {"min_time": 100.0, "max_time": 300.0},
         "numerics": {"stick_scaling": 16}}


def _sim(**over) -> Simulation:
    data = {**SMALL, **over}
    sim = Simulation(build_config(data))
    sim.start_loading()
    return sim


def test_inertia_and_step_scale_together_and_lambda_one_is_exact():
    sim = _sim()
    fresh = Simulation(build_config({**SMALL, "numerics": {"stick_scaling": 1}}))
    fresh.start_loading()
    s, f = sim.state, fresh.state
    dt0 = choose_dt(sim.config)
    set_inertia(sim, 16.0, dt0)
    assert sim.dt == 4.0 * dt0 and sim.params[K.DT] == sim.dt
    np.testing.assert_allclose(s.mass, 16.0 * f.mass, rtol=1e-15)
    np.testing.assert_allclose(s.inv_inertia, f.inv_inertia / 16.0, rtol=1e-15)
    assert sim.params[K.WALL_MASS] == pytest.approx(16.0 * fresh.params[K.WALL_MASS], rel=1e-15)
    assert sim.params[K.DAMPING] * sim.dt == pytest.approx(fresh.params[K.DAMPING] * fresh.dt, rel=1e-15)
    # the stability margin dt / sqrt(m) of every grain is lambda's invariant
    np.testing.assert_allclose(sim.dt * np.sqrt(s.inv_mass), fresh.dt * np.sqrt(f.inv_mass), rtol=1e-14)
    set_inertia(sim, 1.0, dt0)
    for name in ("mass", "inv_mass", "inv_inertia"):
        assert np.array_equal(getattr(s, name), getattr(f, name)), name
    assert np.array_equal(sim.params, fresh.params) and sim.dt == fresh.dt


def _row(sim, v):
    return {"time": 100.0, "wall_vx": v, "thickness": 6.0, "tau_over_sigma": 0.1}


def test_inertial_number_and_guard_lower_lambda(capsys):
    sim = _sim(numerics={"stick_scaling": 16, "stick_inertial_max": 1e-4})
    ctl = StickScaling(sim.config, sim)
    assert ctl.lam == 16.0 and sim.dt == pytest.approx(4.0 * choose_dt(sim.config), rel=1e-15)
    v = 1.2 * 4e-5                                 # quiet: below end_factor V_s = 2 V_s
    expected = v / 6.0 * 1.0 * math.sqrt(16.0 / 3e-4)
    assert ctl.columns(sim, _row(sim, v))["inertial_number"] == pytest.approx(expected, rel=1e-12)
    assert expected > 1e-4
    ctl.after_row(sim, _row(sim, v), None)
    lowered = 16.0 * (0.5 * 1e-4 / expected) ** 2
    assert ctl.lam == pytest.approx(lowered if lowered >= 2 else 1.0)
    assert ctl.counts["lowered"] == 1 and "lowered" in capsys.readouterr().err
    assert sim.params[K.DT] == pytest.approx(choose_dt(sim.config) * math.sqrt(ctl.lam), rel=1e-15)
    # a quiet row below the bound changes nothing
    lam = ctl.lam
    ctl.after_row(sim, _row(sim, 1e-9), None)
    assert ctl.lam == lam


def test_wet_loading_run_above_the_deborah_bound_is_refused():
    wet = {"fluid": {"permeability": 1e-9}}       # slow diffusion: De_stick large
    sim = _sim(**wet)
    sim.start_fluid()
    with pytest.raises(ConfigError, match="numerics.stick_scaling"):
        StickScaling(sim.config, sim)
    fast = _sim(fluid={"permeability": 1e-3}, numerics={"stick_scaling": 4})
    fast.start_fluid()
    assert StickScaling(fast.config, fast).lam == 4.0
    assert "stick_deborah" in StickScaling(fast.config, fast).columns(fast, {**_row(fast, 1e-5), "deborah": 1e-3})


def test_cli_refuses_a_wet_scaled_run_with_exit_2(tmp_path):
    import yaml

    scene = {**SMALL, "name": "wet", "fluid": {"permeability": 1e-9}, "run": {"duration": 100.0}}
    path = tmp_path / "wet.yaml"
    path.write_text(yaml.safe_dump(scene))
    result = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "wet"), "--quiet"])
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert "numerics.stick_scaling" in result.output


def _run(lam, seed, drops, t_load=0.0, duration=1000.0):
    slips = [{"onset_time": t_load + 300.0 + 100.0 * i, "static_strength": 0.3, "stress_drop": d,
              "peak_velocity": 1e-3, "duration": 50.0} for i, d in enumerate(drops)]
    return {"lam": lam, "seed": seed, "steps": int(1000 / math.sqrt(lam)), "wall": 1.0, "n": 10,
            "t_load": t_load, "duration": duration, "i_max": 1e-5, "counts": {}, "slips": slips}


def test_ladder_statistics_and_default():
    runs = [_run(1.0, 1, [0.10, 0.10, 0.10]), _run(1.0, 2, [0.12, 0.12, 0.12]),
            _run(4.0, 1, [0.105, 0.11, 0.115]), _run(4.0, 2, [0.11, 0.11, 0.11]),
            _run(16.0, 1, [0.2, 0.2, 0.2]), _run(16.0, 2, [0.2, 0.2, 0.2])]
    res = summarize(runs, transient=0.2)
    rows = {r["lambda"]: r for r in res["rows"]}
    spread = np.std([0.10, 0.12], ddof=1)
    assert rows[4.0]["stress_drop_spread"] == pytest.approx(spread)
    assert rows[4.0]["stress_drop_diff"] == pytest.approx(0.11 - 0.11)
    assert rows[16.0]["stress_drop_diff"] == pytest.approx(0.09)
    a, b = np.array([0.2] * 6), np.array([0.1] * 3 + [0.12] * 3)
    assert rows[16.0]["stress_drop_ci95"] == pytest.approx(1.96 * math.sqrt(a.var(ddof=1) / 6 + b.var(ddof=1) / 6))
    assert rows[4.0]["within_spread"] and not rows[16.0]["within_spread"]
    assert res["default"] == 4.0
    assert res["cycle"] == pytest.approx(100.0)
    assert rows[16.0]["speedup"] == pytest.approx(1000 / 250)


def test_cycle_projection_counts_the_true_inertia_stretch():
    from gouge_cli.driver.slips import lead_time
    from gouge_cli.driver.stick_scaling import cycle_steps, true_stretch

    config = build_config({**SMALL, "slips": {"lead": 100.0, "merge_gap": 30.0}, "output": {"series_interval": 10.0}})
    dt = choose_dt(config)
    assert cycle_steps(config, 1.0, 1e4, 50.0) == (1e4 / dt, 1e4 / dt)
    plain, scaled = cycle_steps(config, 16.0, 1e4, 50.0)
    true_t = 1.25 * lead_time(config) + 50.0 + max(30.0 + 20.0, 50.0)     # lead, slip, quiet window
    assert scaled == pytest.approx(true_t / dt + (1e4 - true_t + 125.0) / (4.0 * dt), rel=1e-12)
    assert plain / scaled < 4.0
    # a short slip: the quiet window is merge_gap + 2 series intervals, not a second lead
    assert true_stretch(config, 1e4, 10.0) == (125.0 + 10.0 + 50.0, 100.0)
    # a slip longer than the lead: the window is the lead (never longer than the first version's)
    assert true_stretch(config, 1e4, 300.0) == (125.0 + 300.0 + 100.0, 100.0)
    # the structural cap: lambda -> inf still computes the true stretch and the discarded lead
    _, huge = cycle_steps(config, 1e12, 1e4, 50.0)
    assert 1e4 / dt / huge == pytest.approx(1e4 / true_t, rel=1e-4)


def _feed(ctl, sim, recorder, rows):
    """Rows through the recorder and the controller as phases.load_phase does; the time of the
    row at which scaling resumed (None if it did not)."""
    for row in rows:
        slip = recorder.observe(row)
        ctl.after_row(sim, row, recorder, slip)
        if ctl.scaled:
            return row["time"]
    return None


def _slip_rows(V, t_slip, t_end, t_stop, dt=10.0):
    """Wall rows: creep at V/2, a slip at 20 V from t_slip to t_end, creep again to t_stop."""
    rows, x, tau = [], 0.0, 0.3
    for t in np.arange(0.0, t_stop, dt):
        v = 20.0 * V if t_slip <= t < t_end else 0.5 * V
        x += v * dt
        tau += -1e-4 if t_slip <= t < t_end else 1e-6
        rows.append({"time": float(t), "wall_vx": v, "wall_x": x, "tau_over_sigma": tau, "porosity": 0.2,
                     "thickness": 6.0})
    return rows


@pytest.mark.parametrize("merge_gap, lead", [(30.0, 2000.0), (400.0, 2000.0), (30.0, 120.0)])
def test_scaling_resumes_after_the_closed_slip_and_a_quiet_window_tied_to_it(merge_gap, lead):
    """After a rollback the true-inertia stretch slips from t = 100 to 300; scaling resumes once
    the detector has closed that slip (merge_gap after its end) and the wall has been quiet for
    max(merge_gap + 2 series intervals, min(slip duration, lead)), long before a second lead."""
    from gouge_cli.driver.slips import SlipRecorder

    V = 4e-5
    sim = _sim(slips={"lead": lead, "merge_gap": merge_gap, "start_factor": 5, "end_factor": 1.5},
               output={"series_interval": 10.0})
    ctl = StickScaling(sim.config, sim, quiet=True)
    recorder = SlipRecorder(sim.config, sim, None, None)
    ctl.onset_scaled = 0.0                 # as after a rollback: a true-inertia recomputation
    ctl._set(sim, 1.0, rescale=False)
    resumed = _feed(ctl, sim, recorder, _slip_rows(V, 100.0, 300.0, 3000.0))
    assert recorder.count == 1 and recorder.closed()
    duration = recorder.slips[0].duration
    assert duration == pytest.approx(200.0, abs=10.0)
    quiet_from = 300.0                      # first row below end_factor V_s after the slip
    window = max(merge_gap + 20.0, min(duration, lead))
    assert resumed is not None and quiet_from + window <= resumed <= quiet_from + window + 10.0
    assert resumed >= recorder.slips[0].end_time + merge_gap      # the detector closed it first
    assert resumed <= quiet_from + max(merge_gap + 20.0, lead) + 10.0     # the first version's window at most
    assert ctl.lam == 16.0 and ctl.resumed_at == resumed and ctl.slip_span == 0.0
    assert recorder.ring[-1].time == sim.state.time                  # the resume state is kept
    assert recorder.peak_tau == -np.inf                              # with the stress peak afresh
    assert recorder.ring[-1].states["slip_recorder"]["peak_tau"] == -np.inf
    assert ctl.state_dict()["slip_span"] == 0.0


def test_no_resume_while_the_wall_creeps_above_the_end_threshold():
    """Mean wall velocity above end_factor V_s after the slip: no resume, however long."""
    from gouge_cli.driver.slips import SlipRecorder

    V = 4e-5
    sim = _sim(slips={"lead": 2000.0, "merge_gap": 30.0, "start_factor": 5, "end_factor": 1.5},
               output={"series_interval": 10.0})
    ctl = StickScaling(sim.config, sim, quiet=True)
    recorder = SlipRecorder(sim.config, sim, None, None)
    ctl.onset_scaled = 0.0
    ctl._set(sim, 1.0, rescale=False)
    rows = _slip_rows(V, 100.0, 300.0, 1500.0)
    for i, row in enumerate(rows):           # after the slip: quiet rows alternating with 2.9 V rows
        if row["time"] >= 300.0 and i % 2:
            row["wall_vx"] = 2.9 * V
    x = 0.0
    for row in rows:
        x += row["wall_vx"] * 10.0
        row["wall_x"] = x
    assert _feed(ctl, sim, recorder, rows) is None and ctl.lam == 1.0


def test_ladder_keep_reuses_runs_of_the_same_scene_only(tmp_path):
    import json

    from gouge_cli.studies.scaling_ladder import run_ladder, scene_key

    config = build_config({**SMALL, "numerics": {"stick_scaling": 1}})
    key = scene_key(config)
    # seed, lambda and the keys the ladder sets per run do not change the scene; the loading does
    assert scene_key(build_config({**SMALL, "seed": 9, "numerics": {"stick_scaling": 64, "threads": 2}})) == key
    assert scene_key(build_config({**SMALL, "loading": {"spring_constant": 2e-4, "velocity": 8e-6}})) != key
    runs = [dict(_run(lam, seed, drops), scene=key) for lam, seed, drops in
            [(1.0, 3, [0.10] * 3), (1.0, 4, [0.12] * 3), (4.0, 3, [0.11] * 3), (4.0, 4, [0.11] * 3),
             (16.0, 3, [0.2] * 3), (16.0, 4, [0.2] * 3), (1.0, 5, [0.5] * 3)]]
    (tmp_path / "scaling_runs.json").write_text(json.dumps(runs))
    ran = []
    res = run_ladder(config, [4.0], 2, tmp_path, progress=ran.append, keep=True)
    assert ran == [] and not (tmp_path / "lam_1").exists()          # nothing was run again
    assert [r["lambda"] for r in res["rows"]] == [1.0, 4.0]          # only the requested rungs and seeds
    assert {(r["lam"], r["seed"]) for r in res["runs"]} == {(1.0, 3), (1.0, 4), (4.0, 3), (4.0, 4)}
    assert res["rows"][1]["stress_drop_diff"] == pytest.approx(0.0)    # seed 5's 0.5 is not pooled
    assert len(json.loads((tmp_path / "scaling_runs.json").read_text())) == 7   # the file keeps every run
    assert (tmp_path / "scaling_ladder.csv").exists()
    # runs of another scene (or from before the key) are refused, naming the option
    other = dict(runs[0], scene="0" * 16)
    (tmp_path / "scaling_runs.json").write_text(json.dumps(runs + [other]))
    with pytest.raises(ConfigError, match="--keep"):
        run_ladder(config, [4.0], 2, tmp_path, keep=True)
