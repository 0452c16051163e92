"""`gouge regime PAIRS.csv --out DIR`: the regime map's tables and figures again from a pair table,
with nothing simulated; the same numbers as analysis.regime on the same rows."""

from __future__ import annotations

import csv

import pytest
from typer.testing import CliRunner

from gouge_cli.analysis.regime import DELAY_COLUMNS, REGIME_COLUMNS, regime_rows
from gouge_cli.cli.main import app

runner = CliRunner()


def _pairs(path):
    cols = ["kind", "seed", "permeability", "base_type", "complex", "strength_difference", "peak_velocity_ratio",
            "stress_drop_ratio", "duration_ratio", "deborah_onset", "deborah_max", "deborah_mean",
            "drained_onset", "undrained_onset", "transient"]
    rows = [["run", 3] + [""] * (len(cols) - 2)]
    for perm, de in ((1e-5, 0.1), (1e-6, 1.0)):
        for seed in (3, 7, 11):
            for i, (b, v, d) in enumerate((("I", 0.8, -2000), ("II", 1.2, 30000), ("II", 0.9, 9000), ("tie", 0.7, 100))):
                rows.append(["pair", seed, perm, b, i % 2 == 0, -0.01 if b == "I" else 0.01, v, v + 0.05, 1.1,
                             de / 10, de * (1 + 0.1 * i), de / 5, 1e5, 1e5 + d, seed == 3 and i == 3])
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        w.writerows(rows)
    return path


def _read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_gouge_regime_writes_the_map_from_a_pair_table(tmp_path):
    pairs = _pairs(tmp_path / "pairs.csv")
    res = runner.invoke(app, ["regime", str(pairs), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    out = tmp_path / "out"
    for name in ("regime_map.png", "regime_delay.png"):
        assert (out / name).stat().st_size > 10_000
    regime = _read(out / "regime.csv")
    assert list(regime[0]) == REGIME_COLUMNS
    pooled = {float(r["kappa_c"]): r for r in regime if r["seed"] == "all"}
    assert set(pooled) == {1e-5, 1e-6}
    assert int(pooled[1e-5]["n_pairs"]) == 11 and int(pooled[1e-5]["n_seeds"]) == 3     # one transient left out
    expected = [r for r in regime_rows([r for r in _read(pairs) if r["kind"] == "pair"]) if r["seed"] == "all"]
    for e in expected:
        got = pooled[e["kappa_c"]]
        for key in ("type_I", "type_I_lo", "type_I_seed_lo", "type_I_seed_hi", "peak_velocity_ratio_seed_hi"):
            assert float(got[key]) == pytest.approx(e[key], rel=1e-12), key
    delay = _read(out / "delay.csv")
    assert list(delay[0]) == DELAY_COLUMNS
    near = [r for r in delay if r["kappa_c"] == "all" and float(r["delay_from"]) == 0.0][0]
    assert int(near["n_pairs"]) == 2 * (3 + 3 - 1)          # the delays -2000 and 100, one transient


def test_gouge_regime_refuses_a_table_without_pairs(tmp_path):
    bad = tmp_path / "runs.csv"
    bad.write_text("kind,point,seed\nrun,a,3\n")
    res = runner.invoke(app, ["regime", str(bad), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2
    assert "not a pair table" in res.output
    res = runner.invoke(app, ["regime", str(tmp_path / "none.csv"), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2


def test_where_selects_one_value_of_a_swept_column(tmp_path):
    pairs = _pairs(tmp_path / "pairs.csv")
    res = runner.invoke(app, ["regime", str(pairs), "--out", str(tmp_path / "out"), "--where", "seed=7"])
    assert res.exit_code == 0, res.output
    regime = _read(tmp_path / "out" / "regime.csv")
    assert {r["seed"] for r in regime} == {"all"} and int(regime[0]["n_pairs"]) == 4     # one seed: no split
    for bad in (["--where", "nonsense"], ["--where", "packing.n_grains=3640"], ["--where", "seed=99"]):
        res = runner.invoke(app, ["regime", str(pairs), "--out", str(tmp_path / "out2"), *bad])
        assert res.exit_code == 2, (bad, res.output)


def test_by_swept_never_pools_swept_values():
    from gouge_cli.workflows.regime_report import by_swept, select

    rows = [{"seed": s, "loading.normal_stress": sig, "permeability": 1e-5} for sig in ("0.0001", "0.001") for s in (1, 2)]
    groups = by_swept(rows, ["loading.normal_stress", "seed"])
    assert [g for g, _ in groups] == [{"loading.normal_stress": "0.0001"}, {"loading.normal_stress": "0.001"}]
    assert all(len(rs) == 2 for _, rs in groups)
    assert len(select(rows, {"loading.normal_stress": "1e-4"})) == 2          # compared as numbers


def test_the_verdict_summary_counts_the_committed_records():
    """summary.md's rows (the regime page's table) from the verdict campaign's committed records:
    one row per coupling and permeability, whose pair, seed and type counts are the records' own
    (counted here from the pair rows, independently of analysis.regime), with seed-level intervals
    that hold the pooled fraction."""
    from pathlib import Path

    from gouge_cli.workflows.campaign_tables import spec_pairs
    from gouge_cli.workflows.regime_report import SUMMARY_HEADER, by_swept, summary_lines

    spec = Path(__file__).resolve().parents[2] / "examples" / "verdict_seeds.yaml"
    rows, keys = spec_pairs(spec)
    if not rows:
        pytest.skip("no verdict records in this checkout")
    assert keys == ["variant"]
    n_cols = SUMMARY_HEADER[0].count("|") - 1
    for values, group in by_swept(rows, keys):
        perms = sorted({float(r["permeability"]) for r in group})
        lines = summary_lines(group, f"variant = {values['variant']}")
        assert len(lines) == len(perms)
        for line, perm in zip(lines, perms):
            cells = [c.strip() for c in line.strip("|").split("|")]
            assert len(cells) == n_cols and float(cells[2]) == perm
            mine = [r for r in group if float(r["permeability"]) == perm and not r.get("transient")]
            assert int(cells[3]) == len({r["seed"] for r in mine}) and int(cells[4]) == len(mine)
            n1, n2, nt = (int(v) for v in cells[6].split(" / "))
            assert (n1, n2, nt) == tuple(sum(r["base_type"] == t for r in mine) for t in ("I", "II", "tie"))
            for cell in cells[8:11]:     # -C, slower, smaller drop: "p % [lo, hi]s"; one seed: "p %" (no interval)
                values = [float(v) for v in cell.replace("%", "").replace("[", "").replace("]s", "")
                          .replace(",", "").split()]
                assert len(values) == (1 if int(cells[3]) == 1 else 3), cell
                p, lo, hi = values if len(values) == 3 else values * 3
                assert lo <= p <= hi


def test_groups_are_drawn_on_one_figure_and_summarised_never_pooled(tmp_path):
    """Two swept values of a pair table: a folder each, summary.md with one row per (value,
    permeability) counting that value's pairs only, and groups.png with both on one set of axes."""
    from PIL import Image

    from gouge_cli.workflows.regime_report import write_groups

    rows = [r for r in _read(_pairs(tmp_path / "pairs.csv")) if r["kind"] == "pair"]
    for r in rows:
        r["loading.normal_stress"] = "0.001" if r["seed"] == "7" else "0.0003"
    out = write_groups(rows, ["loading.normal_stress"], tmp_path / "out", "sweep")
    lines = (tmp_path / "out" / "summary.md").read_text().splitlines()[2:]
    assert len(lines) == 4                              # 2 stresses x 2 permeabilities
    by_group = {}
    for line in lines:
        cells = [c.strip() for c in line.strip("|").split("|")]
        by_group.setdefault(cells[0], []).append(int(cells[4]))
    # seed 7 alone at 0.001 (4 pairs per permeability); seeds 3 and 11 at 3e-4, seed 3's tie transient
    assert by_group == {"loading.normal_stress = 0.001": [4, 4], "loading.normal_stress = 0.0003": [7, 7]}
    png = Image.open(out["groups_figure"])
    assert png.size[0] > 1000 and "never pooled" in png.info.get("Description", "")


def test_the_verdict_runs_recur_about_as_the_spring_reloads_their_drops():
    """Run rows from the committed verdict records: the mean recurrence against the time the
    spring takes to give back the mean drop, drop sigma / (k V) (recurrence_ratio). Measured on
    seeds 1-6 (2026-12-07): 1.16-1.21, the stick creeping and hardening before each slip; a ratio
    below 1 (the recurrence shorter than the reloading) or a spread wider than the seeds' would mean
    the catalog's drops or recurrences, or the columns, are wrong."""
    from pathlib import Path

    from gouge_cli.workflows.campaign_survey import survey
    from gouge_cli.workflows.campaign_tables import table_rows
    from gouge_cli.workflows.campaign_spec import load_spec

    path = Path(__file__).resolve().parents[2] / "examples" / "verdict_seeds.yaml"
    runs = [r for r in table_rows(survey(load_spec(path), path)) if r["kind"] == "run"]
    if len(runs) < 3:
        pytest.skip("fewer than 3 verdict runs recorded in this checkout")
    for r in runs:
        expect = r["stress_drop_mean"] * 3e-4 / (1e-6 * 2e-4)        # sigma, k and V of verdict_seeds.yaml
        assert r["recurrence_reload"] == pytest.approx(expect, rel=1e-12)
        assert 1.0 < r["recurrence_ratio"] < 1.5, r
    ratios = [r["recurrence_ratio"] for r in runs]
    assert max(ratios) - min(ratios) < 0.15
