"""benchmarks/many_core.py's summary: the figures it reports are the ones in the bench JSON and the
side-by-side results it read (synthetic inputs; the measuring parts need a many-core machine)."""

from __future__ import annotations

import json

import pytest

from benchmark_scripts import load



@pytest.fixture(scope="module")
def many_core():
    return load("many_core")


def _bench():
    rows = []
    for n, base in ((10000, 3.0e7), (40000, 2.5e7)):
        for t, gain in ((1, 1.0), (2, 1.9), (16, 11.0)):
            rows.append({"code": "gouge", "n_grains": n, "threads": t, "steps": 100, "rate_min": base * gain,
                         "rate_median": base * gain, "rate_max": base * gain, "bytes_per_grain": 560.0,
                         "identical_to_1_thread": True})
    rows += [{"code": "lammps-hh", "n_grains": 10000, "threads": t, "steps": 100, "rate_min": r, "rate_median": r,
              "rate_max": r, "bytes_per_grain": None, "identical_to_1_thread": None}
             for t, r in ((1, 1.0e7), (16, 1.5e8))]
    # JSON keys are strings; the paired ratios differ from the ratio of the medians on purpose
    scaling = [{"n_grains": 10000, "paired_ratio": {"2": 1.8, "16": 10.5}, "machine_stream_ratio": {"2": 1.9, "16": 12.0},
                "probe_bytes": 5.6e6},
               {"n_grains": 40000, "paired_ratio": {"2": 1.95, "16": 9.5}, "machine_stream_ratio": {}, "probe_bytes": 2e7}]
    profile = [{"n_grains": 40000, "threads": t, "contact_forces": c, "law_pass": c * 0.6, "sum_pass": c * 0.3,
                "kick_drift": k, "rebuild_per_step": 20.0 / t, "renumber_per_step": 0.5, "whole_step": c + k + 25.0}
               for t, c, k in ((1, 1000.0, 80.0), (16, 100.0, 40.0))]
    return {"machine": {"cpus": 16, "numba_threads": 16}, "dt": 0.89, "skin": 0.2, "rows": rows, "scaling": scaling,
            "profile_us": profile,
            "provenance": {"cpu": {"model": "Test CPU", "vector_width_bits": 512, "numba_target": "testlake"}}}


def _side_by_side(rates, alone=(4.0e7, 6.0e7)):
    def run(rate, i):
        return {"index": i, "rate": rate, "wall_start": 100.0 + 0.1 * i, "wall_end": 115.0 + 0.1 * i}
    return {"n_grains": 10000, "threads_per_run": 2, "seconds": 15.0, "runs": len(rates),
            "alone_before": [run(alone[0], 0)], "together": [run(r, i) for i, r in enumerate(rates)],
            "alone_after": [run(alone[1], 0)]}


def test_scaling_rows_take_the_paired_ratios_and_lammps_at_the_same_rank_count(many_core):
    table = {(r["n_grains"], r["threads"]): r for r in many_core.scaling_table(_bench())}
    assert table[10000, 1]["speedup"] == 1.0 and table[10000, 2]["speedup"] == 1.8
    assert table[40000, 16]["speedup"] == 9.5 and table[40000, 16]["machine_speedup"] is None
    assert table[10000, 16]["machine_speedup"] == 12.0
    assert table[10000, 1]["lammps"]["hh"]["gouge_over"] == pytest.approx(3.0)
    assert table[10000, 16]["lammps"]["hh"]["gouge_over"] == pytest.approx(3.0e7 * 11.0 / 1.5e8)
    assert table[10000, 2]["lammps"] == {} and table[40000, 1]["lammps"] == {}


def test_part_speedups_are_against_the_fewest_threads_of_the_same_size(many_core):
    parts = many_core.part_scaling(_bench())
    sixteen = next(p for p in parts if p["threads"] == 16)
    assert sixteen["speedup"]["contact_forces"] == pytest.approx(10.0)
    assert sixteen["speedup"]["kick_drift"] == pytest.approx(2.0)
    assert sixteen["speedup"]["renumber_per_step"] == pytest.approx(1.0)
    assert sixteen["us"]["whole_step"] == pytest.approx(165.0)


def test_side_by_side_aggregate_is_the_sum_over_the_mean_alone_rate(many_core):
    side = many_core.concurrent_summary(_side_by_side([4.0e7] * 6 + [3.0e7, 2.0e7]))
    assert side["alone_rate"] == pytest.approx(5.0e7)
    assert side["aggregate_rate"] == pytest.approx(2.9e8)
    assert side["aggregate_over_alone"] == pytest.approx(5.8)
    assert side["slowest_over_alone"] == pytest.approx(0.4)
    assert side["overlap"] == pytest.approx(14.3 / 15.7)


@pytest.mark.parametrize("rates, verdict", [([5.0e7] * 8, "met"), ([3.0e7] * 8, "SHORT")])
def test_summary_states_the_targets_and_the_machine(many_core, rates, verdict):
    record, text = many_core.summarize(_bench(), _side_by_side(rates))
    assert record["targets"]["scaling"] == {"n_grains": 40000, "threads": 16, "speedup": 9.5, "target": 10.0}
    assert "16 threads / 1 at 40000 grains: 9.50x (target 10.0x: SHORT)" in text
    ratio = sum(rates) / 5.0e7
    assert record["targets"]["concurrent"]["ratio"] == pytest.approx(ratio)
    assert f"8 runs side by side / one alone: {ratio:.2f}x (target 6.5x: {verdict})" in text
    assert text.startswith("CPU: Test CPU, 16 cores, 512-bit vectors, numba target testlake")
    json.dumps(record)                                   # what the script writes


def test_summary_without_side_by_side_runs_or_sixteen_threads(many_core):
    bench = _bench()
    bench["rows"] = [r for r in bench["rows"] if r["threads"] != 16]
    record, text = many_core.summarize(bench, None)
    assert record["side_by_side"] is None and "concurrent" not in record["targets"]
    assert record["targets"]["scaling"]["threads"] == 2 and record["targets"]["scaling"]["target"] is None
    assert "side by side" not in text and "2 threads / 1 at 40000 grains: 1.95x\n" in text
