"""The benchmark runs and reports what it measured; the example batch script forks every slip."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
from rich.console import Console

from gouge_cli.studies.bench import paired_scaling, prepare, run_benchmark
from gouge_cli.studies.bench_profile import footprint_profile, sub_system
from gouge_cli.studies.bench_report import bench_report
from gouge_cli.kernels import layout as L
from gouge_cli.kernels import forces as F
from gouge_cli.kernels import step as K
from gouge_cli.kernels.probe import stream_probe
from needs import two_threads
from slipping import slipping_run
from factories import scene

REPO = Path(__file__).resolve().parents[2]


@two_threads
def test_benchmark_runs_on_a_tiny_scene():
    """The bench on 1 and 2 threads: rows, the 2-thread state equal to the 1-thread state, the
    paired scaling, fluid shares and profiles (the comparisons need two threads: skipped on one)."""
    results = run_benchmark(sizes=(600,), threads=[1, 2], steps=60, repeats=1, lammps=False, permeability=1e-5)
    rows = results.rows
    threads = [1, 2]
    assert [r.threads for r in rows] == threads
    for r in rows:
        assert r.code == "gouge" and r.n_grains == 600 and r.steps == 60
        assert r.rate_min > 0 and r.bytes_per_grain > 100
        assert r.identical_to_1_thread is True
    assert [sorted(s["paired_ratio"]) for s in results.scaling] == [threads[1:]]
    for s in results.scaling:            # the machine probe ran beside gouge on the same thread counts
        assert sorted(s["machine_stream_ratio"]) == threads[1:] and all(v > 0 for v in s["machine_stream_ratio"].values())
        assert abs(s["probe_bytes"] - 600 * rows[0].bytes_per_grain) < 1e-6 * s["probe_bytes"]
    shares = results.fluid
    assert len(shares) == 3 * len(threads)      # bench dt (auto) and Run 24 dt (auto, implicit), each thread count
    assert [s["solver"] for s in shares] == ["auto"] * 2 * len(threads) + ["implicit"] * len(threads)
    assert all(s["explicit_fraction"] == 0.0 for s in shares if s["solver"] == "implicit")
    assert all(0.0 < s["rate_undrained"] for s in shares)
    # one repeat: the paired share (median of 1 - undrained/dry within repeats) is the share of the medians
    assert all(abs(s["fluid_share_paired"] - s["fluid_share"]) < 1e-12 for s in shares)
    assert {s["fluid_interval_steps"] for s in shares} == {1, 6}     # fluid.step 0.5: 1 step at the bench dt, 6 at 0.09
    parts = results.fluid_profile_us                       # one update's parts at the thesis dt
    assert [f["threads"] for f in parts] == threads and all(f["explicit"] or f["cg_iterations"] >= 1 for f in parts)
    assert all(f["deposit"] > 0 and f["solve"] > 0 and f["drag"] > 0 for f in parts)
    assert all(abs(f["update"] - f["deposit"] - f["solve"] - f["drag"]) < 1e-9 for f in parts)
    assert [a["per_step"] for a in results.allocations] == [0.0] * len(threads)   # none in the step loop
    for prof in results.profile_us:
        assert all(prof[k] > 0 for k in ("contact_forces", "kick_drift", "rebuild_each", "whole_step"))
        assert prof["steps_per_rebuild"] > 5    # (no timing comparisons here: the machine is shared)
    assert results.to_dict()["rows"][0]["code"] == "gouge"          # bench.json's record
    console = Console(record=True, width=200)
    for item in bench_report(results, Path("bench.json")):        # the CLI's report
        console.print(item)
    text = console.export_text()
    assert "grain-steps per second" in text and "microseconds per step" in text and "undrained (kappa_c" in text


def test_stream_probe_is_the_stated_update_for_any_part_count():
    a = np.linspace(0.0, 1.0, 1001)
    expected = np.zeros_like(a)
    for _ in range(3):
        expected = 0.5 * (a + expected)
    for parts in (1, 2, 3, 7):               # parts split the loop; every element gets the same three updates
        b = np.zeros_like(a)
        stream_probe(a, b, parts, 3)
        assert np.array_equal(b, expected)


def test_paired_scaling_is_the_median_of_ratios_within_each_repeat():
    # a slow second repeat (both counts 2x slower) leaves the paired ratios at 1.9; the ratio of the
    # medians of the two columns would mix repeats: median(10, 9, 5) / median(5, 4.7368, 2.5) = 9 / 4.7368
    rates = {1: [5.0, 2.5, 4.7368], 2: [9.5, 4.75, 9.0]}
    got = paired_scaling(rates)
    assert list(got) == [2] and abs(got[2] - 1.9) < 1e-3


def test_footprint_sub_systems_are_the_first_rows_of_the_packing():
    sim, start = prepare(600, 0.89, 0.2)
    s, p = sim.state, sim.params.copy()
    p[L.THREADS] = 1
    grains, lists, pairs = sub_system(s, s.n)   # every pair: the contact pass gives the run's own forces, bit for bit
    F.contact_forces(grains, lists, pairs, np.zeros(0), np.zeros(0), p)
    K.compute_forces(s.grains(), s.lists(), s.pairs(), s.wall, p, np.zeros(0), np.zeros(0))
    assert np.array_equal(grains.force_x, s.force_x) and np.array_equal(grains.torque, s.torque)
    assert np.array_equal(lists.shear, s.shear[:s.start[-1]])
    s.restore(start)
    m = 250
    _, part, _ = sub_system(s, m)       # exactly the listed pairs with both grains below m, in list order
    pairs = [(i, int(s.index[k])) for i in range(m) for k in range(s.start[i], s.start[i + 1]) if s.index[k] < m]
    got = [(i, int(part.index[k])) for i in range(m) for k in range(part.start[i], part.start[i + 1])]
    assert got == pairs and len(pairs) > m
    rows = footprint_profile(sim, start, (m, 600, 5000), repeats=1)
    assert [r["first_grains"] for r in rows] == [m, 600]
    assert all(r["ns_per_grain"] > 0 and r["of_n_grains"] == 600 for r in rows)
    assert rows[0]["working_set_mb"] < rows[1]["working_set_mb"]


def test_batch_script_forks_every_slip(tmp_path):
    batch = scene("batch", 1, run={"duration": 80000}, output={"series_interval": 10, "snapshot_interval": 40000})
    _, run, _ = slipping_run(batch, tmp_path, slips=1)
    bin_dir = Path(sys.executable).parent
    env = dict(os.environ, GOUGE=str(bin_dir / "gouge"), PYTHON=sys.executable)
    catalog = json.loads(subprocess.run([str(bin_dir / "gouge"), "slips", str(run), "--json"], check=True,
                                        capture_output=True, text=True, env=env).stdout)
    kept = [e["number"] for e in catalog if e["checkpoint"]]
    assert kept
    script = REPO / "examples" / "fork_all_slips.sh"
    done = subprocess.run(["bash", str(script), str(run), "1e-3"], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    lines = (run / "forks" / "summary.jsonl").read_text().splitlines()
    assert [json.loads(line)["slip"] for line in lines] == kept
    assert all(set(json.loads(line)["branches"]) == {"drained", "perm_1e-03"} for line in lines)
    again = subprocess.run(["bash", str(script), str(run), "1e-3"], capture_output=True, text=True, env=env)
    assert again.returncode == 0 and "already forked" in again.stdout
