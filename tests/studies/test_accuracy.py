"""Accuracy ladders (gouge_cli.studies.accuracy, `gouge accuracy`): errors fall as the settings are
refined, and the measured orders of the schemes are those of the analytic cases.

Default suite: a 3-level dt ladder on a 300-grain scene from the checkpoint before its first
slip, the quick analytic ladders and the CLI (~10 s). The full ladders are ``validation``.
"""

from __future__ import annotations

import csv
import math
import re

import pytest
from typer.testing import CliRunner

from gouge_cli.studies.accuracy import (analytic_ladders, fit_order, prepare_start, run_accuracy, run_scene_ladders,
                                scene_ladders)
from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.config import build_config
from slipping import slipping_start
from factories import scene

TINY = scene("tiny", 11, run={"duration": 80000})


@pytest.fixture(scope="module")
def start(tmp_path_factory):
    """The tiny scene compacted and loaded to its first slip (the next packing where one gives no
    slip in its loading time, as at seed offset 22); ladders start before its onset."""
    return slipping_start(TINY, tmp_path_factory.mktemp("prepare"))


def errors_of(result, ladder, name):
    group = [r for r in result["results"] if r.level.ladder == ladder and not r.level.reference]
    return [r.errors[name] for r in group]


def test_fit_order_recovers_a_power_law():
    assert fit_order([0.4, 0.2, 0.1], [1.6e-3, 4e-4, 1e-4]) == pytest.approx(2.0)
    assert math.isnan(fit_order([0.4], [1e-3]))
    assert math.isnan(fit_order([0.4, 0.2], [0.0, float("nan")]))


def test_start_is_before_a_slip(start):
    """The start is the slip checkpoint moved up to at most MAX_LEAD_SLIPS slip durations before
    the onset, and the interval runs from there to the slip's end plus 10 %."""
    from gouge_cli.driver.simulation import Simulation
    from gouge_cli.io.checkpoint import read_checkpoint
    from gouge_cli.model.timestep import slip_duration
    from gouge_cli.studies.accuracy import MAX_LEAD_SLIPS, slip_end

    assert re.search(r"checkpoints/slip_\d{3}\.h5$", start.source), start.source
    ck = read_checkpoint(start.source)
    sim = Simulation(start.config, arrays=ck.state)
    onset, end = float(ck.header.onset_time), slip_end(start.source, ck.header)
    begin = max(ck.time, onset - MAX_LEAD_SLIPS * slip_duration(start.config, sim.wall_mass_per_length))
    assert begin < onset < end
    assert start.interval == pytest.approx(1.1 * (end - begin), abs=1.1 * sim.dt)


def test_start_moves_up_to_the_capped_lead(start, tmp_path):
    """A pre-slip checkpoint kept far (here: 20 slip durations) before its onset is advanced to
    MAX_LEAD_SLIPS slip durations before it; without a catalog entry the interval runs from there
    to the onset plus 5 slip durations. The onset is moved in a copy of the fixture's checkpoint,
    so this holds whatever lead the seed's own slip had."""
    import json
    import shutil

    import h5py

    from gouge_cli.model.timestep import slip_duration
    from gouge_cli.studies.accuracy import MAX_LEAD_SLIPS, start_from_checkpoint
    from gouge_cli.io.checkpoint import DIGEST_PREFIX, read_checkpoint
    from gouge_cli.io.integrity import content_digest
    from gouge_cli.driver.simulation import Simulation
    ck = read_checkpoint(start.source)
    duration = slip_duration(start.config, Simulation(start.config, arrays=ck.state).wall_mass_per_length)
    copy = tmp_path / "far.h5"
    shutil.copy(start.source, copy)
    with h5py.File(copy, "r+") as h5:
        extra = json.loads(h5.attrs["extra"])
        extra.pop("slip", None)
        extra["onset_time"] = ck.time + 20.0 * duration
        h5.attrs["extra"] = json.dumps(extra)
        h5.attrs["checksum"] = DIGEST_PREFIX + content_digest(h5)     # an edited checkpoint, stamped again
    moved = start_from_checkpoint(copy, start.config)
    sim = Simulation(moved.config, arrays=moved.state)
    assert sim.state.time == pytest.approx(ck.time + (20.0 - MAX_LEAD_SLIPS) * duration, abs=sim.dt)
    assert moved.interval == pytest.approx((MAX_LEAD_SLIPS + 5.0) * duration, abs=sim.dt)


def test_dt_ladder_errors_fall_with_dt(start):
    """On a window short enough not to be chaotic (the first quarter of the ladder interval: the
    approach to the slip, from MAX_LEAD_SLIPS slip durations before its onset) the wall's errors
    fall with dt at a positive order, for any seed. Measured on the first slips of seeds 11-16, 18
    and 19: coarse / fine wall_vx errors 1.2-8.0e-4 / 0.4-4.2e-4, wall_vx orders 0.9-1.9, wall_x
    orders 0.7-1.6. On the first half of the interval seed 18's wall_vx order was 0.03, and through
    the whole slip the levels part by the chaotic spread (the full ladder reports it), so neither
    is asserted here."""
    import dataclasses
    window = dataclasses.replace(start, interval=0.25 * start.interval)
    result = run_scene_ladders(window, scene_ladders(start.config, quick=True, fluid=False), samples=200)
    assert [r.level.setting for r in result["results"]] == ["dt_safety=0.4", "dt_safety=0.2", "dt_safety=0.1"]
    assert all(r.status == "ok" for r in result["results"])
    assert result["results"][0].steps * 4 == pytest.approx(result["results"][2].steps, rel=1e-3)
    for name in ("wall_x", "wall_vx"):
        coarse, fine = errors_of(result, "dt_safety", name)
        assert 0.0 < fine < coarse < 1e-2, (name, coarse, fine)
    assert 0.5 < result["orders"]["dt_safety"]["wall_vx"] < 3.5


def test_grid_ladder_converges_at_a_fixed_filter_width(start):
    """The pore-fluid coupling at a fixed filter width w = 3 d (kappa_c = 1e-5, forked wet from the
    dry checkpoint) on grids h = w and w/2 against w/4, over the first tenth of the approach to the
    slip: the pressure field (probed at fixed points) gets closer to the finest grid as h falls,
    at a positive order (0.47-0.99 over seed offsets 0, 5, 7, 13, 22, 28, 29, 33 and 38; 0.13 at
    37, where the two grids' errors are close) (on the whole slip of
    the validation page, seed 4: errors 0.19 / 0.067 / 0.035 for h = w, w/2, w/4 against w/8,
    order 1.2). The window is short so that the levels' grain paths stay together: over a quarter
    of the approach, at seed offset 29 the errors of both grids grew to 0.12-0.15 in its last
    tenth as the paths parted before the slip, and the whole window's were 0.054 and 0.054. The
    wall's creep before the slip hardly feels the grid (its error stayed at 0.014 on both grids
    at seed offset 38), so it is not asserted here; through the slip it converges (validation page)."""
    import dataclasses
    window = dataclasses.replace(start, interval=0.1 * start.interval)
    levels = [lv for lv in scene_ladders(start.config, quick=True, fluid=True) if lv.ladder == "grid"]
    assert [lv.setting for lv in levels] == ["cell_size=3", "cell_size=1.5", "cell_size=0.75"]
    result = run_scene_ladders(window, levels, samples=100)
    assert all(r.status == "ok" for r in result["results"])
    coarse, fine = errors_of(result, "grid", "pressure_field")
    assert 0.0 < fine < coarse, (coarse, fine)
    assert result["orders"]["grid"]["pressure_field"] > 0.0


def test_analytic_orders_quick():
    result = analytic_ladders(quick=True)
    orders = result["orders"]
    assert 1.7 < orders["energy drift"]["energy"] < 2.4
    assert 1.7 < orders["head-on collision"]["contact_time"] < 2.3
    assert 1.7 < orders["Terzaghi (implicit)"]["pressure"] < 2.5
    assert 1.7 < orders["Terzaghi (explicit)"]["pressure"] < 2.5
    assert 1.4 < orders["block on a spring"]["slip"] < 2.5
    energy = [r.errors["energy"] for r in result["rows"] if r.case == "energy drift"]
    assert energy == sorted(energy, reverse=True)


def test_cli_writes_table_csv_and_figure(start, tmp_path):
    out = tmp_path / "acc"
    result = CliRunner().invoke(app, ["accuracy", "--slip-checkpoint", start.source, "--quick", "--no-analytic",
                                      "--no-fluid", "--samples", "100", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "observed order (dt_safety)" in result.output and "dt_safety=0.4" in result.output
    rows = list(csv.DictReader((out / "accuracy.csv").open()))
    assert [r["setting"] for r in rows] == ["dt_safety=0.4", "dt_safety=0.2", "dt_safety=0.1"]
    # through the whole slip the errors need not fall level by level (chaotic spread): they are
    # finite, positive and small, and the finest level is the reference
    assert all(0.0 < float(r["error_wall_x"]) < 0.05 for r in rows[:2]), rows
    assert rows[2]["reference"] == "1" and rows[2]["error_wall_x"] == ""
    assert (out / "accuracy.png").stat().st_size > 10_000


def test_cli_needs_a_scene():
    result = CliRunner().invoke(app, ["accuracy"])
    assert result.exit_code == EXIT_BAD_INPUT and "--slip-checkpoint" in result.output


@pytest.mark.validation
def test_full_ladders(tmp_path):
    """Every ladder on the tiny scene (fixture seed, shifted by GOUGE_TEST_SEED_OFFSET) runs, and
    the analytic orders are 2 (collision, energy, Terzaghi) and ~2 for the block's slip. Through a
    whole slip the levels part by the chaotic spread (wall_vx dt order 0.19 for seed 18; from seeds
    11-15 the wall_x order was 0.54-1.26), so convergence is asserted on the first quarter of the
    window, which is not chaotic: the wall's dt errors fall from the coarsest to the finest of five
    levels at a positive order, and the fluid-step pressure error falls at every level at first
    order (backward Euler: 1.09-1.29 over seeds 11 and 18, where the whole window gave 0.32-1.26)."""
    import dataclasses
    result = run_accuracy(build_config(TINY), tmp_path, quick=False)
    scene = result["scene"]
    assert all(r.status == "ok" for r in scene["results"])
    assert len(errors_of(scene, "dt_safety", "wall_x")) == 5
    start = prepare_start(build_config(TINY), tmp_path / "window")
    window = dataclasses.replace(start, interval=0.25 * start.interval)
    levels = [lv for lv in scene_ladders(start.config, quick=False, fluid=True)
              if lv.ladder in ("dt_safety", "fluid.step")]
    short = run_scene_ladders(window, levels, samples=200)
    for name in ("wall_x", "wall_vx"):
        errs = errors_of(short, "dt_safety", name)
        assert errs[0] > errs[-1] > 0.0, (name, errs)
    assert short["orders"]["dt_safety"]["wall_vx"] > 0.5
    errs = errors_of(short, "fluid.step", "pressure")
    assert all(a > b for a, b in zip(errs, errs[1:])), errs
    assert short["orders"]["fluid.step"]["pressure"] > 0.8
    orders = result["analytic"]["orders"]
    assert 1.8 < orders["energy drift"]["energy"] < 2.3
    assert 1.8 < orders["head-on collision"]["contact_time"] < 2.2
    assert 1.8 < orders["Terzaghi (implicit)"]["pressure"] < 2.3
    assert 1.5 < orders["block on a spring"]["slip"] < 2.3
    assert (tmp_path / "accuracy.csv").is_file() and (tmp_path / "accuracy.png").is_file()
