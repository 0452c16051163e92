"""`gouge campaign` on a real Dask LocalCluster (2 worker processes): a 2 x 2 study end to end,
one worker killed in the middle of a run, results bitwise equal to serial `gouge run` /
`gouge restart`, re-running does nothing, changed settings are refused, the SLURM job script."""

from __future__ import annotations

import math
import os
import shlex
import signal
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.io.checkpoint import read_checkpoint
from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.workflows.campaign import run_campaign
from gouge_cli.workflows.campaign_survey import status_lines, survey
from gouge_cli.workflows.campaign_tasks import read_ledger
from gouge_cli.workflows.campaign_spec import load_spec
from gouge_cli.workflows.executors import ClusterOptions, local_cluster, slurm_cluster
from factories import fork_at

SCENE = {
    "name": "tiny", "seed": 1,
    "packing": {"n_grains": 200, "width": 12},
    "loading": {"spring_constant": 2e-4, "velocity": 1e-4},
    "numerics": {"dt_safety": 0.3},
    "run": {"duration": 20000},
    "slips": {"start_factor": 5, "end_factor": 1.5, "merge_gap": 300},
    "output": {"series_interval": 10, "snapshot_interval": 10000, "checkpoint_interval": 2000},
}
SPEC = {
    "name": "t2x2", "base": "tiny.yaml", "out": "campaigns",
    "sweep": {"grid": {"loading.normal_stress": [3.0e-4, 3.5e-4]}, "seeds": [1, 2]},
    "action": "study", "study": {"permeabilities": [1.0e-3], "duration": 800},
}
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def write_spec(folder: Path, name: str, **changes) -> Path:
    spec = {**SPEC, **changes}
    path = folder / name
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def series(path: Path) -> dict:
    with h5py.File(path, "r") as h5:
        return {k: v[...] for k, v in h5["series"].items()}


def assert_same_run(a: Path, b: Path):
    """Every series row, the final state and every kept slip state equal, bit for bit."""
    sa, sb = series(a / "run.h5"), series(b / "run.h5")
    assert sa.keys() == sb.keys()
    for name in sa:
        assert np.array_equal(sa[name], sb[name], equal_nan=True), name
    for ck in ["latest.h5"] + [Path(e.checkpoint).name for e in slip_catalog(a) if e.checkpoint]:
        x, y = read_checkpoint(a / "checkpoints" / ck).state, read_checkpoint(b / "checkpoints" / ck).state
        for name in x:
            assert np.array_equal(x[name], y[name]), (ck, name)
    assert [e.onset_time for e in slip_catalog(a)] == [e.onset_time for e in slip_catalog(b)]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("campaign")
    (path / "tiny.yaml").write_text(yaml.safe_dump(SCENE))
    return path


@pytest.fixture(scope="module")
def client():
    from distributed import Client

    with local_cluster(ClusterOptions(workers=2)) as cluster, Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def campaign(folder, client, monkeypatch_module):
    """The 2 x 2 study on the cluster; the worker running one point's run is killed (SIGKILL)
    after that run wrote a checkpoint."""
    monkeypatch_module.chdir(folder)
    spec = write_spec(folder, "spec.yaml")
    root = folder / "campaigns" / "t2x2"
    killed = {}

    def killer():
        deadline = time.time() + 120
        while time.time() < deadline and not killed:
            for ledger in root.glob("*/ledger/run.json"):
                record = read_ledger(ledger) or {}
                if record.get("state") == "running" and (ledger.parent.parent / "checkpoints" / "latest.h5").is_file():
                    os.kill(int(record["pid"]), signal.SIGKILL)
                    killed.update(point=ledger.parent.parent.name, pid=record["pid"])
                    return
            time.sleep(0.02)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    lines = []
    report = run_campaign(spec, client=client, cluster=ClusterOptions(retries=1), log=lines.append)
    thread.join()
    return {"spec": spec, "root": root, "report": report, "killed": killed, "log": lines}


@pytest.fixture(scope="module")
def monkeypatch_module():
    mp = pytest.MonkeyPatch()
    yield mp
    mp.undo()


def test_spec_unknown_keys_are_refused_by_name(folder):
    path = folder / "bad.yaml"
    path.write_text(yaml.safe_dump({**SPEC, "sweep": {"gird": {"loading.velocity": [1e-5]}}, "acton": "run"}))
    result = gouge("campaign", path)
    assert result.exit_code == EXIT_BAD_INPUT
    assert "sweep.gird: unknown key" in result.output and "acton: unknown key" in result.output
    path.write_text(yaml.safe_dump({**SPEC, "set": {"loading.velocty": 1e-5}}))
    result = gouge("campaign", path, "--status")
    assert result.exit_code == EXIT_BAD_INPUT and "loading.velocty" in result.output


def test_campaign_runs_to_the_end_after_a_worker_is_killed(campaign):
    report, root = campaign["report"], campaign["root"]
    assert campaign["killed"], "no run was caught in the middle of a task"
    assert report.finished == {"done": report.submitted} and not report.survey.by_state("left", "failed")
    record = read_ledger(root / campaign["killed"]["point"] / "ledger" / "run.json")
    assert record["state"] == "done" and record["attempts"] == 2 and record["result"]["resumed"]
    assert record["pid"] != campaign["killed"]["pid"]
    points = sorted(p.name for p in root.iterdir() if (p / "point.yaml").is_file())
    assert len(points) == 4
    for name in points:
        state = yaml.safe_load((root / name / "point.yaml").read_text())
        assert state["overrides"]["loading.normal_stress"] in (3.0e-4, 3.5e-4) and state["overrides"]["seed"] in (1, 2)
        assert state["config"]["loading"]["normal_stress"] == state["overrides"]["loading.normal_stress"]
    kept = {n: [e.number for e in slip_catalog(root / n) if e.checkpoint] for n in points}
    assert sum(map(len, kept.values())) >= 1, "no slip in four stick-slip runs"
    for n, slips in kept.items():
        assert sorted(int(p.name[5:]) for p in (root / n / "forks").glob("slip_*")) == slips


def test_point_on_a_worker_is_bitwise_gouge_run_and_restart(campaign, folder):
    """Serial `gouge run` of each point (the command in its state-point file) and `gouge restart`
    of one forked slip give the campaign's files bit for bit, the killed-and-resumed point included."""
    root = campaign["root"]
    forked = None
    for pdir in sorted(p for p in root.iterdir() if (p / "point.yaml").is_file()):
        state = yaml.safe_load((pdir / "point.yaml").read_text())
        args = shlex.split(state["command"])
        assert args[:2] == ["gouge", "run"]
        serial = folder / "serial" / pdir.name
        args[-1] = str(serial)
        result = gouge(*args[1:], "--quiet")
        assert result.exit_code == 0, result.output
        assert_same_run(pdir, serial)
        slips = sorted((pdir / "forks").glob("slip_*"))
        if forked is None and slips:
            forked = (pdir, serial, int(slips[0].name[5:]))
    pdir, serial, slip = forked
    result = gouge("restart", serial, "--slip", slip, "--perm", "1e-3", "--duration", 800, "--quiet")
    assert result.exit_code == 0, result.output
    for branch in ("drained", "perm_1e-03"):
        a = series(fork_at(pdir, slip).root / branch / "run.h5")
        b = series(fork_at(serial, slip).root / branch / "run.h5")
        for name in a:
            assert np.array_equal(a[name], b[name], equal_nan=True), (branch, name)


def test_table_and_phase_diagram(campaign):
    import csv

    root = campaign["root"]
    rows = list(csv.DictReader(open(root / "table.csv")))
    runs = [r for r in rows if r["kind"] == "run"]
    pairs = [r for r in rows if r["kind"] == "pair"]
    assert len(runs) == 4 and {r["loading.normal_stress"] for r in runs} == {"0.0003", "0.00035"}
    n_forks = sum(1 for _ in root.glob("*/forks/slip_*/pair.json"))
    assert len(pairs) == n_forks and all(r["permeability"] == "0.001" for r in pairs)
    for r in runs:
        assert int(r["n_slips"]) == len(slip_catalog(root / r["point"]))
    cells = list(csv.DictReader(open(root / "phase_diagram.csv")))
    assert len(cells) == 2 and {c["y"] for c in cells} == {"0.0003", "0.00035"}
    assert sum(int(c["n_pairs"]) + int(c["n_unclassified"]) for c in cells) == len(pairs)
    for c in cells:
        n = int(c["n_pairs"])
        inside = [r for r in pairs if r["loading.normal_stress"] == c["y"] and r["base_type"] != "none"]
        assert n == len(inside) and int(c["n_type_II"]) == sum(r["base_type"] == "II" for r in inside)
        if n:
            assert float(c["frac_complex"]) == pytest.approx(sum(r["complex"] == "True" for r in inside) / n)
    for name in ("phase_diagram.png", "slip_statistics.png", "pairs_perm_1e-03.png", "recurrence.png"):
        assert (root / "figures" / name).stat().st_size > 10_000
    # the loading cycle per normal stress (a sigma sweep): every run counted, stick-slip or not
    cycles = list(csv.DictReader(open(root / "recurrence.csv")))
    assert [(c["sigma"], int(c["n_runs"])) for c in cycles] == [("0.0003", 2), ("0.00035", 2)]
    for c in cycles:
        mine = [r for r in runs if r["loading.normal_stress"] == c["sigma"]]
        assert int(c["n_stick_slip"]) == sum(int(r["n_slips"]) >= 2 for r in mine)
        assert int(c["n_stick_slip"]) + int(c["n_one_slip"]) + int(c["n_steady"]) == 2
    assert any(line.startswith("phase cell permeability=0.001") for line in campaign["log"])
    finished = [line for line in campaign["log"] if line.startswith("[") and " finished, " in line]
    assert any("; ETA ~" in line for line in finished)                 # once a fork and a run are timed
    assert finished[-1].endswith("ETA ~0:00:00")                        # nothing left after the last


def test_the_eta_is_what_is_left_at_the_medians_so_far():
    from gouge_cli.workflows.campaign import campaign_eta

    seconds = {"run": [3000.0, 5000.0, 4000.0], "fork": [200.0, 100.0, 300.0]}
    # 10 forks queued, 2 loadings to run with 15 slips each: (10 x 200 + 2 x (4000 + 15 x 200)) / 2 slots
    assert campaign_eta(seconds, 10, 2, 15, 2) == pytest.approx(8000.0)
    assert campaign_eta(seconds, 0, 0, 15, 2) == 0.0
    assert math.isnan(campaign_eta({"run": [3000.0], "fork": []}, 4, 0, 15, 2))       # no fork timed yet
    assert math.isnan(campaign_eta({"run": [], "fork": [100.0]}, 4, 1, 15, 2))        # no loading timed yet
    assert campaign_eta({"run": [], "fork": [100.0]}, 4, 0, 15, 1) == pytest.approx(400.0)


def test_local_workers_have_one_numba_thread_per_task(client):
    from gouge_cli.workflows.executors import oversubscribed

    assert set(client.run(lambda: os.environ["NUMBA_NUM_THREADS"]).values()) == {"1"}
    assert oversubscribed(client) == []


def test_rerun_does_nothing_and_status_says_done(campaign, client):
    root = campaign["root"]
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}
    report = run_campaign(campaign["spec"], client=client)
    assert report.submitted == 0 and report.outputs == {}
    assert {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()} == before
    result = gouge("campaign", campaign["spec"], "--status")
    assert result.exit_code == 0
    n = len(report.survey.pieces)
    assert f"4 points, {n} pieces known: {n} done, 0 running, 0 failed, 0 left" in result.output


def test_changed_spec_adds_points_and_refuses_changed_settings(campaign, folder):
    more = write_spec(folder, "more.yaml", sweep={**SPEC["sweep"], "seeds": [1, 2, 3]})
    s = survey(load_spec(more), more)
    states = [(p.piece.kind, p.state) for p in s.pieces]
    assert states.count(("run", "left")) == 2 and ("run", "conflict") not in states
    assert len(s.by_state("done")) == len(campaign["report"].survey.pieces)
    changed = write_spec(folder, "changed.yaml", set={"run.duration": 25000})
    result = gouge("campaign", changed)
    assert result.exit_code == EXIT_BAD_INPUT
    assert "run.duration: 20000.0 -> 25000.0" in result.output and "--force" in result.output
    forks = write_spec(folder, "forks.yaml", study={"permeabilities": [1.0e-3], "duration": 900})
    lines = status_lines(survey(load_spec(forks), forks))
    assert any("conflict" in line and "duration: 800.0 -> 900.0" in line for line in lines) == \
        bool(list(campaign["root"].glob("*/forks/slip_*")))


@pytest.mark.filterwarnings("ignore:Port 8787")
def test_slurm_job_script_has_the_requested_resources():
    opts = ClusterOptions(threads_per_task=2, slurm=True, slurm_cores=8, slurm_memory="16GB",
                          slurm_walltime="02:00:00", slurm_queue="short", slurm_account="geo").check()
    cluster = slurm_cluster(opts)
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    for line in ("#SBATCH --cpus-per-task=8", "#SBATCH --mem=16G", "#SBATCH -t 02:00:00", "#SBATCH -p short",
                 "#SBATCH -A geo", "export NUMBA_NUM_THREADS=2"):
        assert line in script, line
    assert "--nworkers 4" in script and "--nthreads 1" in script and "--lifetime 6900s" in script


def test_existing_scheduler_runs_a_campaign(campaign, client, folder):
    spec = folder / "short.yaml"
    spec.write_text(yaml.safe_dump({"name": "short", "base": "tiny.yaml", "set": {"run.duration": 3000},
                                    "sweep": {"points": [{"loading.normal_stress": 3.0e-4}]}}))
    result = gouge("campaign", spec, "--scheduler", client.scheduler.address)
    assert result.exit_code == 0, result.output
    assert "1 points, 1 pieces known: 1 done" in result.output
    run_dir = next((folder / "campaigns" / "short").glob("*/run.h5")).parent
    with h5py.File(run_dir / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished"
    assert read_ledger(run_dir / "ledger" / "run.json")["pid"] in client.run(os.getpid).values()


def test_open_campaign_equals_the_table(campaign):
    """gouge_cli.api.open_campaign (from the campaign file or its folder): the rows of table.csv."""
    import csv

    from gouge_cli.api import open_campaign

    root = campaign["root"]
    rows = list(csv.DictReader(open(root / "table.csv")))
    for df in (open_campaign(campaign["spec"]), open_campaign(root)):
        assert len(df) == len(rows) and list(df["kind"]) == [r["kind"] for r in rows]
        for (_, got), want in zip(df.iterrows(), rows):
            assert got["point"] == want["point"] and got["seed"] == int(float(want["seed"]))
            if want["kind"] == "run":
                assert got["n_slips"] == int(want["n_slips"])
                assert got["stress_drop_mean"] == pytest.approx(float(want["stress_drop_mean"]), rel=1e-12, nan_ok=True)
            else:
                assert got["type"] == want["type"] and got["slip"] == int(float(want["slip"]))
                assert got["permeability"] == pytest.approx(float(want["permeability"]))
        assert set(df[df["kind"] == "pair"].groupby("loading.normal_stress").size().index) <= {3.0e-4, 3.5e-4}
