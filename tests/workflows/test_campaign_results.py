"""Campaign results that outlive the machine (issue 59), on a real Dask LocalCluster and real
run files: a study campaign with two fluid variants is run whole once (the reference); a second
copy is run on part of the sweep, its run folders deleted and one fork record removed (a point
interrupted in its forks), and then, from its results folder alone on a fresh folder, resumed
on the whole sweep: it runs only what is missing (the lost loading again, bitwise, and the one
fork) and its tables equal the reference's byte for byte. Results folders of one spec merge;
records made with other settings are refused, naming the key."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest
import yaml

from gouge_cli.errors import CampaignConflict
from gouge_cli.workflows.campaign import run_campaign
from gouge_cli.workflows.campaign_survey import status_lines, survey
from gouge_cli.workflows.campaign_results import PieceRecord, Results, merge
from gouge_cli.workflows.campaign_spec import load_spec
from gouge_cli.workflows.executors import ClusterOptions

from test_campaign import SCENE          # the 200-grain stick-slip scene of the campaign tests

SPEC = {
    "name": "durable", "base": "tiny.yaml", "out": "campaigns",
    "sweep": {"seeds": [1, 2]},
    "action": "study",
    "study": {"permeabilities": [1.0e-3], "duration": 800,
              "variants": {"w3": {}, "w4": {"fluid.filter_width": 4.0}}},
}
TABLES = ("table.csv", "phase_diagram_w3.csv", "phase_diagram_w4.csv")


def _folder(root: Path, **changes) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "tiny.yaml").write_text(yaml.safe_dump(SCENE))
    spec = {**SPEC, **changes}
    (root / "spec.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return root / "spec.yaml"


@pytest.fixture(scope="module")
def client():
    from distributed import Client

    from gouge_cli.workflows.executors import local_cluster

    with local_cluster(ClusterOptions(workers=2)) as cluster, Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def reference(tmp_path_factory, client):
    root = tmp_path_factory.mktemp("reference")
    spec = _folder(root)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        report = run_campaign(spec, client=client, log=lambda m: None)
    assert not report.survey.by_state("failed", "left")
    return root, report


def _tables(root: Path) -> dict[str, bytes]:
    return {name: (root / "campaigns" / "durable" / name).read_bytes() for name in TABLES}


def test_reference_has_pairs_of_every_variant(reference):
    root, report = reference
    with open(root / "campaigns" / "durable" / "table.csv", newline="") as f:
        pairs = [r for r in csv.DictReader(f) if r["kind"] == "pair"]
    assert {p["variant"] for p in pairs} == {"w3", "w4"}
    assert {float(p["filter_width"]) for p in pairs} == {3.0, 4.0}
    n_forks = len(list(report.survey.results.root.glob("*/fork_*.json")))
    assert n_forks >= 1, "no slip was forked in two stick-slip runs"
    assert len(pairs) == 2 * n_forks          # one pair per variant and slip (one permeability)
    # the drained twin is shared: the w4 fork's drained branch is a link to the point's
    for pdir in (root / "campaigns" / "durable").glob("seed-*"):
        for fork in (pdir / "variants" / "w4" / "forks").glob("slip_*"):
            assert (fork / "drained").is_symlink()


def test_records_are_small_and_self_describing(reference):
    root, report = reference
    for path in report.survey.results.root.glob("*/*.json"):
        assert path.stat().st_size < 64_000
        data = json.loads(path.read_text())
        assert data["campaign"] == "durable" and data["digest"] == PieceRecord.from_json(path.read_text()).digest
        assert {"git_commit", "cpu", "numba_target"} <= set(data["machine"])
        # the piece's CPU time: spent (compiles and steps), and no more than its wall time allows
        # (one numba thread and the worker's own threads: at most ~2 cores' worth)
        assert 0.0 < data["cpu_seconds"] <= 2.0 * data["wall_seconds"] + 1.0
        if data["piece"] == "run":
            assert len(data["result"]["final_state_hash"]) == 16 and data["result"]["values"]["seed"] in (1, 2)


def test_resume_from_results_alone_gives_the_same_tables(reference, tmp_path, client):
    ref_root, ref = reference
    # a first machine runs seed 1 only, then is lost: only its results folder is kept
    first = tmp_path / "first"
    spec = _folder(first, sweep={"seeds": [1]})
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(first)
        run_campaign(spec, client=client, log=lambda m: None)
    results = first / "campaigns" / "durable" / "results"
    forks = sorted(results.glob("seed-1_*/fork_*.json"))
    assert forks, "seed 1 has no forked slip"
    forks[-1].unlink()                      # that point was interrupted in its last fork
    # a fresh checkout: the spec, the scene and the results folder, no run folder
    fresh = tmp_path / "fresh"
    spec = _folder(fresh)
    shutil.copytree(results, fresh / "campaigns" / "durable" / "results")
    lines = []
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(fresh)
        s = survey(load_spec(spec), spec)
        status = "\n".join(status_lines(s))
        assert "its run folder is gone" in status
        report = run_campaign(spec, client=client, log=lines.append)
    ran = [line.split("] ", 1)[1].split(":")[0] for line in lines if line.startswith("[")]
    seed1 = [r for r in ran if r.startswith("seed-1_")]
    assert sorted(seed1) == sorted([f"{forks[-1].parent.name} run", f"{forks[-1].parent.name} {forks[-1].stem}"])
    assert not report.survey.by_state("left", "failed", "conflict")
    assert _tables(fresh) == _tables(ref_root)


def test_merge_and_refusal(reference, tmp_path):
    ref_root, ref = reference
    src = ref.survey.results
    a, b = Results(tmp_path / "a"), Results(tmp_path / "b")
    for (point, piece), record in src.records().items():
        (a if point.startswith("seed-1_") else b).write(record)
    written = merge(a, b, "durable")
    assert len(written) == len(b.records())
    assert {k: r.to_json() for k, r in a.records().items()} == {k: r.to_json() for k, r in src.records().items()}
    # the same piece with other settings is refused, naming the key; nothing is copied
    c = Results(tmp_path / "c")
    key, record = next((k, r) for k, r in src.records().items() if r.piece != "run")
    c.write(PieceRecord(**{**record.__dict__, "settings": {**record.settings, "duration": 900.0}}))
    d = Results(tmp_path / "d")
    d.write(src.records()[key])
    other = next(r for k, r in src.records().items() if k != key)
    d.write(other)
    with pytest.raises(CampaignConflict, match=r"duration: 900.0 -> 800.0"):
        merge(c, d, "durable")
    assert len(c.records()) == 1
    with pytest.raises(CampaignConflict, match="of campaign 'durable', not 'other'"):
        merge(Results(tmp_path / "e"), d, "other")


def test_changed_settings_conflict_with_the_records(reference, tmp_path):
    """A results folder alone still guards its settings: a spec with another branch length
    finds every fork record in conflict, naming the key."""
    ref_root, ref = reference
    fresh = tmp_path / "changed"
    spec = _folder(fresh, study={**SPEC["study"], "duration": 900})
    shutil.copytree(ref.survey.results.root, fresh / "campaigns" / "durable" / "results")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(fresh)
        s = survey(load_spec(spec), spec)
        conflicts = s.by_state("conflict")
        assert conflicts and all(c.piece.kind == "fork" for c in conflicts)
        assert all("duration: 800.0 -> 900.0" in c.detail for c in conflicts)
        with pytest.raises(CampaignConflict, match="duration: 800.0 -> 900.0"):
            run_campaign(spec, log=lambda m: None)


def test_tables_only_from_results(reference, tmp_path):
    ref_root, ref = reference
    fresh = tmp_path / "tables"
    spec = _folder(fresh)
    shutil.copytree(ref.survey.results.root, fresh / "campaigns" / "durable" / "results")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(fresh)
        report = run_campaign(spec, tables_only=True, log=lambda m: None)
    assert report.submitted == 0 and not list((fresh / "campaigns" / "durable").glob("seed-*"))
    assert _tables(fresh) == _tables(ref_root)


def test_reanalyse_brings_a_new_column_to_the_records(reference, tmp_path):
    """A record written before a pair column existed gets it from its run folder (--reanalyse),
    keeping its settings and wall time; the table then equals the reference's."""
    ref_root, ref = reference
    copy = tmp_path / "copy"
    shutil.copytree(ref_root, copy, symlinks=True)
    results = Results(copy / "campaigns" / "durable" / "results")
    key, old = next((k, r) for k, r in results.records().items() if r.piece != "run")
    stripped = [{k: v for k, v in row.items() if k != "pressure_from_rate"} for row in old.result["pairs"]]
    results.write(PieceRecord(**{**old.__dict__, "result": {**old.result, "pairs": stripped}}))
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(copy)
        run_campaign(copy / "spec.yaml", tables_only=True, reanalysed=True, log=lambda m: None)
    again = results.read(*key)
    assert again.result["pairs"] == old.result["pairs"] and again.wall_seconds == old.wall_seconds
    assert again.digest == old.digest and "reanalysed" in again.result
    assert _tables(copy) == _tables(ref_root)


def test_a_campaign_without_records_gets_them_from_its_folders(reference, tmp_path):
    """A campaign folder made before results records existed (ledgers and run folders only): the
    records are written from its folders (backfill) and the tables are the same."""
    ref_root, _ = reference
    copy = tmp_path / "old"
    shutil.copytree(ref_root, copy, symlinks=True)
    shutil.rmtree(copy / "campaigns" / "durable" / "results")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(copy)
        report = run_campaign(copy / "spec.yaml", tables_only=True, log=lambda m: None)
    assert len(report.survey.results.records()) == len(Results(ref_root / "campaigns" / "durable" / "results").records())
    assert _tables(copy) == _tables(ref_root)
