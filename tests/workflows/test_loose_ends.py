"""Loose ends of the reliability work: overflowing or underflowing config values are exit 2 naming
the key; `gouge restart` stopped by a full disk or by Ctrl-C (exit 3 / 130) leaves its fork in a
state that the command it names finishes without --force, and classifies no pair of an
interrupted branch; a long run asks before it starts (or needs --yes off a terminal), and a
refused or killed start leaves nothing a later run trips over."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_PHYSICS, AnalysisError
from slipping import slipping_run
from gouge_cli.workflows.pairs import branch_status, write_pair_json
from factories import fork_at

ROOT = Path(__file__).resolve().parents[2]
SCENE = {
    "name": "loose", "seed": 1,
    "packing": {"n_grains": 200, "width": 12},
    "loading": {"spring_constant": 2e-4, "velocity": 1e-4},
    "numerics": {"dt_safety": 0.3, "threads": 1},
    "run": {"duration": 5000},
    "slips": {"start_factor": 5, "end_factor": 1.5, "merge_gap": 300},
    "output": {"series_interval": 10, "snapshot_interval": 10000, "checkpoint_interval": 1000},
}
runner = CliRunner()


def gouge(*args, **kw):
    return runner.invoke(app, [str(a) for a in args], **kw)


# --------------------------------------------------------------------------- overflow, underflow

@pytest.mark.parametrize("section, key, value", [
    ("material", "youngs_modulus", 1e308), ("material", "density", 1e308), ("packing", "diameter_min", 1e-300),
    ("material", "youngs_modulus", 1e-300), ("loading", "normal_stress", 1e-300),
])
def test_extreme_values_are_exit_2_naming_the_key(tmp_path, section, key, value):
    cfg = tmp_path / "extreme.yaml"
    cfg.write_text(yaml.safe_dump({**SCENE, section: {**SCENE.get(section, {}), key: value}}))
    for args in (["config", cfg], ["run", cfg, "--out", tmp_path / "out"]):
        result = gouge(*args)
        assert result.exit_code == EXIT_BAD_INPUT, result.output
        assert f"{section}.{key} = {value:g}" in result.output and "not a finite positive number" in result.output
        assert "Traceback" not in result.output and "ZeroDivisionError" not in result.output
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- restart: full disk, Ctrl-C

@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    """The scene run with a slip kept with its checkpoint: (run directory, that slip's number)."""
    _, run_dir, slips = slipping_run(SCENE, tmp_path_factory.mktemp("loose"), slips=1, grow=1.5)
    return run_dir, slips[0]


def _on_row(monkeypatch, branch: str, after: int, action):
    """Call ``action()`` at the ``after``-th series row written into ``branch`` (a fork branch name)."""
    import gouge_cli.driver.phases as phases

    real, calls = phases.ensure_space, {"n": 0}

    def patched(out_dir, need):
        if Path(out_dir).name == branch:
            calls["n"] += 1
            if calls["n"] == after:
                action(out_dir)
        return real(out_dir, need)

    monkeypatch.setattr(phases, "ensure_space", patched)
    return calls


def _restart(run_dir, slip, *extra):
    return gouge("restart", run_dir, "--slip", slip, "--perm", "1e-3", "--duration", 600, "--quiet", *extra)


def test_full_disk_in_restart_names_the_command_that_continues(loaded, monkeypatch):
    run_dir, slip = loaded
    fork = fork_at(run_dir, slip).root

    def full(out_dir):
        raise OSError(errno.ENOSPC, "No space left on device", str(out_dir))

    _on_row(monkeypatch, "perm_1e-03", 5, full)
    result = _restart(run_dir, slip)
    assert result.exit_code == EXIT_PHYSICS, result.output
    text = " ".join(result.output.split())
    assert "no space left on device" in text and f"gouge restart {run_dir} --slip {slip} --perm 1e-03" in text
    assert "no --force needed" in text and "gouge resume" not in text
    assert branch_status(fork / "drained") == "finished"
    assert branch_status(fork / "perm_1e-03") == "missing"      # nothing half-written under run.h5
    assert not [p for p in (fork / "perm_1e-03").iterdir() if ".tmp" in p.name]
    assert not (fork / "pair.json").exists()
    monkeypatch.undo()
    again = _restart(run_dir, slip)           # the named command, no --force
    assert again.exit_code == 0, again.output
    assert branch_status(fork / "perm_1e-03") == "finished" and (fork / "pair.json").is_file()
    refused = _restart(run_dir, slip)         # everything finished: --force is needed
    assert refused.exit_code == EXIT_BAD_INPUT and "--force" in refused.output


def test_ctrl_c_in_restart_exits_130_and_classifies_nothing(loaded, monkeypatch):
    run_dir, slip = loaded
    fork = fork_at(run_dir, slip).root
    assert _restart(run_dir, slip, "--force").exit_code == 0
    (fork / "pair.json").unlink()
    calls = _on_row(monkeypatch, "drained", 5, lambda out_dir: os.kill(os.getpid(), signal.SIGINT))
    result = _restart(run_dir, slip, "--force")
    assert calls["n"] >= 5
    assert result.exit_code == EXIT_INTERRUPTED, result.output
    text = " ".join(result.output.split())
    assert "branch drained of slip" in text and "no pair was classified" in text
    assert f"gouge restart {run_dir} --slip {slip} --perm 1e-03" in text
    assert branch_status(fork / "drained") == "interrupted"
    assert not (fork / "pair.json").exists()
    with pytest.raises(AnalysisError, match="interrupted"):
        write_pair_json(fork)
    analyzed = gouge("analyze", run_dir, "--json")
    assert analyzed.exit_code == 0 and f"slip {slip}" not in [p.get("slip") for p in
                                                             json.loads(analyzed.stdout or "{}").get("pairs", [])]
    monkeypatch.undo()
    again = _restart(run_dir, slip)           # an unfinished fork: no --force needed
    assert again.exit_code == 0, again.output
    assert branch_status(fork / "drained") == "finished" and (fork / "pair.json").is_file()


# --------------------------------------------------------------------------- long runs

def _long(folder: Path) -> Path:
    cfg = folder / "long.yaml"
    cfg.write_text(yaml.safe_dump({**SCENE, "packing": {"n_grains": 20000, "width": 200}, "run": {"duration": 1e6}}))
    return cfg


def test_long_run_needs_yes_off_a_terminal_and_a_refused_start_writes_nothing(tmp_path, monkeypatch):
    cfg, out = _long(tmp_path), tmp_path / "long"
    result = gouge("run", cfg, "--out", out)
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert "not started" in result.output and "--yes" in result.output and " h at " in result.output
    assert not out.exists()
    import gouge_cli.cli.common as common

    monkeypatch.setattr(common, "interactive", lambda: True)       # a terminal: the user is asked
    declined = gouge("run", cfg, "--out", out, input="n\n")
    assert declined.exit_code == EXIT_BAD_INPUT, declined.output
    assert "Start it?" in declined.output and not out.exists()


def test_killed_start_leaves_nothing_a_later_run_trips_over(tmp_path):
    """`gouge run --yes` of the long config killed (SIGKILL) before its first checkpoint; a later
    `gouge run` into the same directory starts without --force."""
    cfg, out = _long(tmp_path), tmp_path / "long"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               NUMBA_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-m", "gouge_cli.cli", "run", str(cfg), "--out", str(out), "--yes",
                             "--quiet"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.time() + 300
        while not (out / "config.yaml").exists() and proc.poll() is None and time.time() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.stderr.read().decode()
        proc.kill()
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert (out / ".gouge.lock").exists() and (out / "config.yaml").exists()
    assert not (out / "checkpoints" / "latest.h5").exists()
    short = tmp_path / "short.yaml"
    short.write_text(yaml.safe_dump({**SCENE, "run": {"duration": 200},
                                     "compaction": {"max_time": 300, "min_time": 100}}))
    result = gouge("run", short, "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    with h5py.File(out / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished" and yaml.safe_load(h5.attrs["config"])["run"]["duration"] == 200
