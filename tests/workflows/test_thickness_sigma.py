"""The thickness and confining-stress figures of issue 63, from pair tables and results records
alone: `gouge regime` on several labelled inputs (a thickness sweep beside the thin layer's
verdict pairs, w3 only) writes groups.csv / groups.png with per-cell counts equal to the
inputs', seed-level intervals that hold the pooled value and collapse where every seed agrees;
a table.csv of a thickness sweep is split by thickness, never pooled; the phase diagram carries
each cell's measured De and places the thesis at its (kappa_c, sigma)."""

from __future__ import annotations

import csv
import math
import statistics
from pathlib import Path

import pytest
import yaml
from PIL import Image
from typer.testing import CliRunner

from gouge_cli.analysis.regime import COMPARED, GROUP_COLUMNS, THESIS_NORMAL_STRESS, thesis_point
from gouge_cli.cli.main import app

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[2]
VERDICT = ROOT / "campaigns" / "verdict_seeds" / "results"
COLS = ["kind", "point", "packing.n_grains", "run.duration", "seed", "variant", "permeability", "base_type",
        "complex", "strength_difference", "peak_velocity_ratio", "stress_drop_ratio", "duration_ratio",
        "deborah_onset", "deborah_max", "deborah_drained", "drained_onset", "undrained_onset", "transient"]


def _pair(n_grains, seed, perm, base_type, complex_, v_ratio, drop_ratio, de, variant="", transient=False) -> dict:
    return {"kind": "pair", "point": f"n{n_grains}-s{seed}", "packing.n_grains": n_grains,
            "run.duration": 2.5e6 if n_grains < 5000 else 3.0e6, "seed": seed, "variant": variant,
            "permeability": perm, "base_type": base_type, "complex": complex_,
            "strength_difference": 0.01 if base_type == "II" else -0.01, "peak_velocity_ratio": v_ratio,
            "stress_drop_ratio": drop_ratio, "duration_ratio": 1.1, "deborah_onset": de / 10, "deborah_max": 0.8 * de,
            "deborah_drained": de, "drained_onset": 1e5, "undrained_onset": 1e5 + 1000, "transient": transient}


def _thick_rows() -> list[dict]:
    """Two thicknesses x two kappa_c x three seeds. At 6920 grains and 2e-5 every pair of every
    seed is Type II, not -C, slower (ratio 0.8) and smaller-drop (0.9): the seeds agree exactly.
    At 3640 and 6e-6 seed 1's pairs are all -C and seeds 2 and 3 have none: they disagree."""
    rows = []
    for n in (3640, 6920):
        for perm, de in ((6e-6, 0.5), (2e-5, 0.12)):
            for seed in (1, 2, 3):
                for i in range(4 + seed):                    # 5, 6, 7 pairs: seeds of unequal size
                    if n == 6920 and perm == 2e-5:
                        rows.append(_pair(n, seed, perm, "II", False, 0.8, 0.9, de * (1 + 0.01 * i)))
                    else:
                        rows.append(_pair(n, seed, perm, ("I", "II", "tie")[i % 3], seed == 1 if n == 3640 else i % 2 == 0,
                                          0.7 + 0.1 * i, 1.2 - 0.1 * seed, de * (1 + 0.05 * i)))
    rows.append(_pair(3640, 1, 6e-6, "II", True, 0.5, 0.5, 0.5, transient=True))    # left out: transient
    rows.append(_pair(3640, 2, 6e-6, "none", False, math.nan, math.nan, 0.5))        # not classified
    return rows


def _thin_rows() -> list[dict]:
    """The thin layer's pairs on two couplings, w3 and w4 (only w3 is to be drawn)."""
    return [_pair(2000, seed, perm, "II" if i % 2 else "tie", i == 0, 0.85, 0.95, de, variant=variant)
            for variant in ("w3", "w4") for perm, de in ((1e-5, 0.1), (3e-6, 0.35)) for seed in (1, 2)
            for i in range(3 if variant == "w3" else 5)]


def _write(rows: list[dict], path: Path) -> Path:
    """A table.csv of the rows; the variant column only where the rows have variants (as a campaign's)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = [c for c in COLS if c != "variant" or any(r["variant"] for r in rows)]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, cols, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    return path


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _counted(rows: list[dict]) -> list[dict]:
    return [r for r in rows if not r["transient"]]


def test_thickness_groups_beside_the_thin_layer(tmp_path):
    thick = _thick_rows()
    thin = _thin_rows()
    a = _write(thick, tmp_path / "verdict_thickness" / "table.csv")
    b = _write(thin, tmp_path / "verdict_seeds" / "table.csv")
    out = tmp_path / "out"
    res = runner.invoke(app, ["regime", str(a), f"thin layer={b}", "--where", "variant=w3", "--out", str(out),
                              "--title", "thickness"])
    assert res.exit_code == 0, res.output
    cells = _read(out / "groups.csv")
    assert list(cells[0]) == GROUP_COLUMNS
    groups = {c["group"] for c in cells}
    assert groups == {"verdict_thickness: packing.n_grains = 3640, run.duration = 2500000.0",
                      "verdict_thickness: packing.n_grains = 6920, run.duration = 3000000.0", "thin layer"}
    for c in cells:
        perm = float(c["kappa_c"])
        if c["group"] == "thin layer":
            mine = [r for r in thin if r["variant"] == "w3" and r["permeability"] == perm]     # never w4
        else:
            n = int(c["group"].split("= ")[1].split(",")[0])
            mine = [r for r in _counted(thick) if r["packing.n_grains"] == n and r["permeability"] == perm]
        classified = [r for r in mine if r["base_type"] != "none"]
        assert int(c["n_pairs"]) == len(mine) and int(c["n_classified"]) == len(classified)
        assert int(c["n_seeds"]) == len({r["seed"] for r in mine})
        assert int(c["n_type_II"]) == sum(r["base_type"] == "II" for r in classified)
        assert int(c["n_complex"]) == sum(bool(r["complex"]) for r in classified)
        assert int(c["n_slower"]) == sum(r["peak_velocity_ratio"] < 1 for r in classified)
        assert float(c["type_II"]) == pytest.approx(int(c["n_type_II"]) / len(classified))
        assert c["de_column"] == "deborah_drained"           # the slip's De, not kappa_c
        assert float(c["de_median"]) == pytest.approx(statistics.median(r["deborah_drained"] for r in mine))
        assert float(c["de_max_median"]) == pytest.approx(statistics.median(r["deborah_max"] for r in mine))
        for key in COMPARED:
            v, lo, hi = (float(c[f"{key}{s}"]) for s in ("", "_seed_lo", "_seed_hi"))
            assert lo <= v + 1e-12 and v <= hi + 1e-12, (c["group"], perm, key)
    # every group's maps in its own folder, the thin layer's under its label
    assert len(list((out / "verdict_thickness").glob("*/regime.csv"))) == 2
    assert (out / "thin_layer" / "regime.csv").is_file()
    png = Image.open(out / "groups.png")
    assert png.size[0] > 1000 and "never pooled" in png.info.get("Description", "")


def test_seed_intervals_collapse_where_seeds_agree_and_widen_where_they_do_not(tmp_path):
    a = _write(_thick_rows(), tmp_path / "thick" / "table.csv")
    res = runner.invoke(app, ["regime", str(a), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    cells = {(c["group"].split(",")[0], float(c["kappa_c"])): c for c in _read(tmp_path / "out" / "groups.csv")}
    assert len(cells) == 4           # a single table.csv of two thicknesses: split by thickness, never pooled
    agree = cells[("packing.n_grains = 6920", 2e-5)]
    for key, value in (("type_II", 1.0), ("complex", 0.0), ("slower", 1.0), ("smaller_drop", 1.0),
                       ("peak_velocity_ratio", 0.8), ("stress_drop_ratio", 0.9)):
        assert [float(agree[f"{key}{s}"]) for s in ("", "_seed_lo", "_seed_hi")] == pytest.approx([value] * 3), key
    split = cells[("packing.n_grains = 3640", 6e-6)]
    assert float(split["complex"]) == pytest.approx(5 / 18)          # seed 1's 5 of the 5 + 6 + 7 classified
    assert float(split["complex_seed_lo"]) == 0.0 and float(split["complex_seed_hi"]) > 0.7
    # one thickness by hand: one map, at the folder itself
    res = runner.invoke(app, ["regime", str(a), "--out", str(tmp_path / "one"), "--where", "packing.n_grains=6920"])
    assert res.exit_code == 0, res.output
    assert {float(r["kappa_c"]) for r in _read(tmp_path / "one" / "regime.csv")} == {6e-6, 2e-5}


def test_several_inputs_are_checked(tmp_path):
    a = _write(_thick_rows(), tmp_path / "x" / "table.csv")
    b = _write(_thin_rows(), tmp_path / "y" / "table.csv")
    for args in ([f"same={a}", f"same={b}"], [str(a), str(b), "--where", "nonsense.key=1"],
                 [str(a), str(b), "--where", "variant=w9"]):
        res = runner.invoke(app, ["regime", *args, "--out", str(tmp_path / "out")])
        assert res.exit_code == 2, (args, res.output)


def _records_table(path: Path, seeds: int = 3) -> list[dict]:
    """The pair rows of the verdict campaign's committed fork records of its first ``seeds``
    points (read as records, whatever coupling revision made them), with the seed and transient
    columns table_rows adds."""
    from gouge_cli.workflows.campaign_results import Results

    records = Results(VERDICT).records()
    runs = sorted((p for p, piece in records if piece == "run"), key=lambda p: records[(p, "run")].result["values"]["seed"])
    rows = []
    for point in runs[:seeds]:
        run = records[(point, "run")].result
        transient = set(run.get("transient", ()))
        for (p, piece), rec in sorted(records.items()):
            if p == point and piece != "run":
                rows += [{**pair, "kind": "pair", "seed": run["values"]["seed"],
                          "transient": int(pair["slip"]) in transient} for pair in rec.result["pairs"]]
    if rows:
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return rows


def test_the_thin_layer_from_real_records_counts_w3_only(tmp_path):
    """The thin layer's points from the verdict campaign's own records, w3 only, beside a
    (constructed) thickness table: the thin group's pairs and seeds per kappa_c are the records'."""
    thin = _records_table(tmp_path / "verdict.csv")
    if not any(r["variant"] == "w3" for r in thin):
        pytest.skip("no verdict fork records in this checkout")
    a = _write(_thick_rows(), tmp_path / "verdict_thickness" / "table.csv")
    res = runner.invoke(app, ["regime", str(a), f"thin={tmp_path / 'verdict.csv'}", "--where", "variant=w3",
                              "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    cells = [c for c in _read(tmp_path / "out" / "groups.csv") if c["group"] == "thin"]
    w3 = [r for r in thin if r["variant"] == "w3" and not r["transient"]]
    assert {float(c["kappa_c"]) for c in cells} == {float(r["permeability"]) for r in w3}
    for c in cells:
        mine = [r for r in w3 if float(r["permeability"]) == float(c["kappa_c"])]
        assert int(c["n_pairs"]) == len(mine) and int(c["n_seeds"]) == len({r["seed"] for r in mine})
        de = [float(r["deborah_drained"]) for r in mine if math.isfinite(float(r["deborah_drained"]))]   # (a pair
        assert float(c["de_median"]) == pytest.approx(statistics.median(de))     # whose drained twin has no De has none)


def test_the_thesis_point_is_its_configs():
    """The thesis's sigma and kappa_c on the phase diagram are those of its runs (configs/thesis)."""
    configs = [yaml.safe_load(p.read_text()) for p in sorted((ROOT / "configs" / "thesis").glob("*.yaml"))]
    assert configs
    assert {float(c["loading"]["normal_stress"]) for c in configs} == {THESIS_NORMAL_STRESS}     # (YAML reads 1e-05 as text)
    wet = {float(c["fluid"]["permeability"]) for c in configs if c.get("fluid")}
    t = thesis_point()
    assert wet == {t.kappa_c} and t.at("permeability") == 1e-5 and t.at("loading.normal_stress") == 3e-4
    assert t.at("packing.n_grains") is None


def test_phase_diagram_carries_measured_de_and_places_the_thesis(tmp_path):
    from gouge_cli.analysis.campaign_table import PHASE_COLUMNS, phase_cells
    from gouge_cli.plots.phase import phase_diagram_figure

    rows = [dict(_pair(2000, seed, perm, "II", i % 2 == 0, 0.8, 0.9, de * (1 + 0.1 * i)),
                 **{"loading.normal_stress": sigma})
            for sigma in (1e-4, 3e-4, 1e-3) for perm, de in ((1e-5, 0.1), (1e-6, 1.0)) for seed in (1, 2) for i in range(3)]
    cells = phase_cells(rows, "permeability", "loading.normal_stress")
    assert len(cells) == 6 and all(set(PHASE_COLUMNS) <= set(c) for c in cells)
    for c in cells:
        mine = [r["deborah_drained"] for r in rows if r["permeability"] == c["x"]
                and r["loading.normal_stress"] == c["y"]]
        assert c["n_pairs"] == 6 and c["n_seeds"] == 2 and c["de_column"] == "deborah_drained"
        assert c["de_median"] == pytest.approx(statistics.median(mine)) and c["de_min"] == min(mine)
        assert c["frac_complex_lo"] <= c["frac_complex"] <= c["frac_complex_hi"]
    old = phase_cells([{k: v for k, v in r.items() if k != "deborah_drained"} for r in rows],
                      "permeability", "loading.normal_stress")
    assert old[0]["de_column"] == "deborah_max"               # a table from before the slip's De
    png = Image.open(phase_diagram_figure(cells, "permeability", "loading.normal_stress", tmp_path / "p.png",
                                          "sigma", thesis_point()))
    assert "the thesis placed" in png.info["Description"]
    off = [c for c in cells if c["y"] != 1e-4]
    for c in off:
        c["y"] *= 10                                       # sigma 3e-3 and 1e-2: the thesis is off the map
    png = Image.open(phase_diagram_figure(off, "permeability", "loading.normal_stress", tmp_path / "q.png",
                                          "sigma", thesis_point()))
    assert "the thesis placed" not in png.info["Description"]
