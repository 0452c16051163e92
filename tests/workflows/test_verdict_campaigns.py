"""Reduced versions of the verdict's campaigns (issue 47) end to end: each spec in examples/ is
cut to one seed, two points and two permeabilities on the 200-grain scene of the reduced regime
map, with its run lengths scaled down in proportion, and run through `gouge campaign` on a real
Dask LocalCluster. Checks that the spec's structure runs: every piece done, a run row per point,
pairs at both permeabilities, and the regime outputs written per swept value (never pooled)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import yaml

from gouge_cli.workflows.campaign import run_campaign
from gouge_cli.workflows.campaign_spec import load_spec
from gouge_cli.workflows.executors import ClusterOptions

from test_regime_campaign import SCENE          # the reduced regime map's 200-grain scene

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
STUDY_FREE, TINY_WALLS = 2000 - 2 * 180, 2 * 12          # free grains of the study scene; walls of the tiny one
SCALE = SCENE["run"]["duration"] / 2.5e6                  # the study scene's 2.5e6 t0 -> the tiny scene's 60,000
pytestmark = pytest.mark.validation      # make validate; measured 3.5 (seeds), 4 (thickness), 13 (sigma) min on 2 shared cores


def _reduced(name: str, folder: Path) -> Path:
    spec = load_spec(EXAMPLES / name).model_dump(exclude_defaults=True)
    tiny_free = SCENE["packing"]["n_grains"] - TINY_WALLS

    def shrink(point: dict) -> dict:
        out = dict(point)
        if "packing.n_grains" in out:                       # the same multiple of the free grains
            out["packing.n_grains"] = TINY_WALLS + round(tiny_free * (out["packing.n_grains"] - 360) / STUDY_FREE)
        if "run.duration" in out:
            out["run.duration"] = round(out["run.duration"] * SCALE)
        return out

    points = [shrink(p) for p in spec["sweep"].get("points", [])]
    points = [points[0], points[-1]] if points else []
    perms = sorted(spec["study"]["permeabilities"])[-2:]     # the two most permeable: short, stable forks
    reduced = {"name": spec["name"] + "_reduced", "base": "tiny.yaml", "out": str(folder / "campaigns"),
               "sweep": {"seeds": [spec["sweep"]["seeds"][0]], **({"points": points} if points else {})},
               "action": "study", "study": {"permeabilities": perms, "duration": 800}}
    if "phase" in spec and "seed" not in spec["phase"].values():     # one seed: the seed is not swept
        reduced["phase"] = spec["phase"]
    (folder / "tiny.yaml").write_text(yaml.safe_dump(SCENE))
    path = folder / f"{name}"
    path.write_text(yaml.safe_dump(reduced))
    return path


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("name", ["verdict_seeds.yaml", "verdict_thickness.yaml", "verdict_sigma.yaml"])
def test_reduced_verdict_campaign(name, tmp_path):
    spec_path = _reduced(name, tmp_path)
    spec = load_spec(spec_path)
    report = run_campaign(spec_path, cluster=ClusterOptions(workers=1), log=lambda m: None)
    assert not report.survey.by_state("failed")
    root = tmp_path / "campaigns" / spec.name
    table = _rows(root / "table.csv")
    runs = [r for r in table if r["kind"] == "run"]
    assert len(runs) == max(1, len(spec.sweep.points))
    pairs = [r for r in table if r["kind"] == "pair"]
    assert pairs, "no slip was forked: the reduced scene is too short for this spec's run lengths"
    for point in {r["point"] for r in pairs}:
        perms = {float(r["permeability"]) for r in pairs if r["point"] == point}
        assert perms == set(spec.study.permeabilities)
    keys = [k for k in spec.swept_keys() if k != "seed"]
    if not keys:
        assert {float(r["kappa_c"]) for r in _rows(root / "regime.csv")} == set(spec.study.permeabilities)
    else:                                                    # one regime map per swept value, none pooled
        combos = {tuple(r[k] for k in keys) for r in pairs}
        written = sorted((root / "regime").glob("*/regime.csv"))
        assert len(written) == len(combos)
        kept = sum(r["transient"] != "True" for r in pairs)
        pooled = [r for path in written for r in _rows(path) if r["seed"] == "all"]
        assert sum(int(r["n_pairs"]) for r in pooled) == kept
