"""Compaction's progress toward its settling criterion (gouge_cli.driver.settling, progress.SettleReport):
the fraction reaches 1 on the check that settles and the ETA extrapolates the time to settle,
not the time to compaction.max_time."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from gouge_cli.config import build_config
from gouge_cli.driver.progress import SettleReport, format_eta
from gouge_cli.io.provenance import sim_hash
from gouge_cli.driver.settling import SettleCheck, SettleTracker
from gouge_cli.driver.callbacks import Callback
from gouge_cli.driver.compaction import Settling, compact
from gouge_cli.io.checkpoint import LEGACY_START, Checkpoint, split_extra
from gouge_cli.driver.simulation import Simulation

SCENE = {"packing": {"n_grains": 300, "width": 15}}     # default compaction: min_time 500, max_time 50,000 t0


def test_exponential_decay_gives_the_exact_time_to_settle():
    """Speeds decaying as r = r0 exp(-t / tau): after two checks the remaining time is
    ln r / (1 / tau), rounded up to the next check; the fraction is ln-linear in r."""
    tau, r0, v_tol = 300.0, 1e4, 1e-3
    settle_at = 100.0 * math.ceil(tau * math.log(r0) / 100.0)          # first check with r < 1
    tracker = SettleTracker(max_time=50_000.0)
    for k in range(1, int(settle_at / 100) + 1):
        t = 100.0 * k
        r = r0 * math.exp(-t / tau)
        check = SettleCheck(t, 0.5 * r * v_tol, r * v_tol, v_tol, min_time=500.0)
        out = tracker.update(check, wall_seconds=0.01 * t)
        if k >= 2:
            assert out["remaining"] == pytest.approx(settle_at - t)
            assert out["eta"] == pytest.approx(0.01 * (settle_at - t))
            assert not out["capped"]
        if t < settle_at:
            assert out["fraction"] < 1.0 and out["unmet"]
            expected = min(t / 500.0, 1.0 - math.log(r) / math.log(r0 * math.exp(-100.0 / tau)))
            assert out["fraction"] == pytest.approx(expected)
    assert check.settled and out["fraction"] == 1.0 and out["remaining"] == 0.0 and out["unmet"] == []


def test_min_time_and_unmet_conditions_are_named():
    tracker = SettleTracker(max_time=1000.0)
    check = SettleCheck(200.0, wall_vz=-3e-3, rms=5e-4, v_tol=1e-3, min_time=500.0)
    assert check.unmet() == ["min_time (200 / 500 t0)", "|wall vz| = 3 v_tol"]
    out = tracker.update(check, 1.0)
    assert math.isinf(tracker._speed_time_left(math.log(3.0)))      # one point: no slope yet
    assert out["capped"] and out["remaining"] == 800.0              # capped at max_time - elapsed
    quiet = SettleCheck(300.0, wall_vz=1e-4, rms=5e-4, v_tol=1e-3, min_time=500.0)
    out = tracker.update(quiet, 2.0)
    assert out["unmet"] == ["min_time (300 / 500 t0)"]
    assert out["fraction"] == pytest.approx(0.6) and out["remaining"] == 200.0
    assert format_eta(math.inf) == "?" and format_eta(3725.0, capped=True) == "<= 1:02:05"


def test_settle_report_prints_progress_toward_the_criterion(capsys):
    report = SettleReport(max_time=1000.0, n_grains=10, live=False, every_s=0.0)
    report.update(SettleCheck(100.0, 2e-3, 1e-3, 1e-3, 500.0), step=10)
    report.update(SettleCheck(600.0, 1e-4, 1e-4, 1e-3, 500.0), step=20)
    lines = capsys.readouterr().err.strip().splitlines()
    assert "waiting for min_time (100 / 500 t0), |wall vz| = 2 v_tol, rms grain speed = 1 v_tol" in lines[0]
    assert lines[1].startswith("compaction: 100% settled, t = 600 t0, criterion met,") and lines[1].endswith("ETA 0:00:00")


def test_progress_and_eta_on_a_small_scene(single_thread):
    """A 300-grain compaction observed by SettleTracker: the fraction is below 1 until the check
    that settles and 1 there; it mostly rises; once it passes 0.5 the median ratio of predicted to
    actual remaining simulated time is within a factor 2 (0.67-1.67 over seed offsets 0-59; a
    single prediction is not: the first after 0.5 was off 3.7x at offset 43 and 7x at 46, one
    later 36x at 11), and the wall ETA is finite and its median within a factor 4 of the actual
    wall time left. Observing changes no bit."""
    config = build_config(SCENE)
    plain = Simulation(config)
    compact(plain)
    sim = Simulation(config)
    tracker = SettleTracker(config.compaction.max_time)
    rows = []
    t_wall = time.perf_counter()

    def observe(s, settling):
        assert settling.check.elapsed == s.state.time - settling.start[0]
        out = tracker.update(settling.check, time.perf_counter() - t_wall)
        rows.append((settling.check.elapsed, time.perf_counter() - t_wall, out))

    settling = Settling(sim)
    compact(sim, [OnCheck(settling, observe)], settling)
    assert settling.settled and sim_hash(sim) == sim_hash(plain)
    end_t, end_wall = rows[-1][0], rows[-1][1]
    fractions = np.array([out["fraction"] for _, _, out in rows])
    assert fractions[-1] == 1.0 and (fractions[:-1] < 1.0).all()
    assert np.max(fractions[:-1] - fractions[1:]) <= 0.3
    half = len(fractions) // 2
    assert fractions[half:].mean() > fractions[:half].mean() + 0.2
    late = [(t, w, out) for t, w, out in rows[:-1] if out["fraction"] >= 0.5]
    assert late, "the fraction never passed 0.5 before settling"
    ratios = [out["remaining"] / (end_t - t) for t, _, out in late]
    assert 1 / 2 <= float(np.median(ratios)) <= 2, ratios
    assert all(math.isfinite(out["eta"]) for _, _, out in late)
    wall_ratios = [out["eta"] / (end_wall - w) for _, w, out in late]
    assert 1 / 4 <= float(np.median(wall_ratios)) <= 4, wall_ratios


def test_compaction_resumed_on_a_check_ends_where_it_would_have(single_thread):
    """Compaction is Simulation.run with its checks every 100 t0 counted from where it began: a
    state saved on its second check and resumed with that start checks that step again first,
    then the same steps, and ends on the same check with the same bits."""
    config = build_config({**SCENE, "compaction": {"min_time": 300, "max_time": 5000}})
    plain = Simulation(config)
    checks, saved = [], {}

    def keep(s, settling):
        checks.append((s.state.step, settling.check.elapsed, settling.check.settled))
        if len(checks) == 2:
            saved.update(arrays=s.state.arrays(), state=settling.state_dict())

    settling = Settling(plain)
    assert compact(plain, [OnCheck(settling, keep)], settling) is settling
    assert len(checks) > 3 and checks[-1][2] and settling.settled
    assert [c[0] for c in checks] == [(k + 1) * plain.steps_for(100.0) for k in range(len(checks))]
    resumed = Simulation(config, arrays=saved["arrays"])
    again = []
    restored = Settling(resumed)            # (a checkpoint before the callback model: its legacy key)
    legacy = split_extra({"phase": "compaction", LEGACY_START: saved["state"]["start"]})
    compact(resumed, [OnCheck(restored, lambda s, st: again.append((s.state.step, st.check.elapsed,
                                                                     st.check.settled)))], restored,
            resume_from=Checkpoint(config, saved["arrays"], {}, *legacy))
    assert restored.start == settling.start
    assert again == checks[1:] and restored.settled
    assert sim_hash(resumed) == sim_hash(plain)


class OnCheck(Callback):
    """fn(sim, settling) on each of compaction's checks."""

    name = "observe"

    def __init__(self, settling, fn):
        self.settling, self.fn = settling, fn

    def act(self, sim):
        self.fn(sim, self.settling)


def test_run_progress_eta_leaves_out_the_compile(monkeypatch, capsys):
    """The plain progress line's rate and ETA count from the first update: a first interval of 30 s
    (numba compiling) followed by 1 s per 1 % of the run gives an ETA of ~98 s at 2 %, not the
    ~1,500 s that the time since the start would give."""
    from gouge_cli.driver import progress as P

    clock = iter([0.0, 30.0, 31.0, 32.0])
    monkeypatch.setattr(P.time, "perf_counter", lambda: next(clock))
    report = P.ProgressReport("loading", 100.0, 1000, live=False, every_s=0.0)
    report.update(0.0, 10)                   # 30 s: the compile
    report.update(1.0, 20)                   # 1 s for 1 % (10 steps of 1,000 grains)
    report.update(2.0, 30)
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].endswith("ETA ? ") and "0.00 M grain-steps/s" in lines[0]
    assert "0.01 M grain-steps/s" in lines[1] and "ETA 0:01:39" in lines[1]
    assert "ETA 0:01:38" in lines[2]
