"""How gouge installs: `make demo` takes the runtime dependencies only (the extras come with
`make test` and `make docs`), and a wheel built from the checkout installs into a clean virtual
environment and runs a tiny scene (CI only: it needs the package index and a few minutes; .ci/run
sets GOUGE_WHEEL_TEST=1)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _dry_run(target: str, venv: Path) -> list[str]:
    """The commands `make TARGET` would run for a fresh .venv at ``venv``."""
    proc = subprocess.run(["make", "-n", "-C", str(ROOT), f"VENV={venv}", target], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.splitlines()


@pytest.mark.skipif(shutil.which("make") is None, reason="GNU make is not installed")
def test_make_demo_installs_the_runtime_dependencies_only(tmp_path):
    venv = tmp_path / "venv"
    installs = [line for line in _dry_run("demo", venv) if "pip install" in line and "-c " in line]
    assert installs and all("-e ." in line and "[" not in line for line in installs), installs
    test = [line for line in _dry_run("test", venv) if "pip install" in line and "-c " in line]
    assert any("'.[test,docs]'" in line for line in test), test
    docs = [line for line in _dry_run("docs", venv) if "pip install" in line and "-c " in line]
    assert any("'.[docs]'" in line for line in docs) and not any(".[test" in line for line in docs), docs


@pytest.mark.skipif(os.environ.get("GOUGE_WHEEL_TEST") != "1",
                    reason="builds a wheel and a clean venv from the package index (minutes): CI sets GOUGE_WHEEL_TEST=1")
def test_wheel_installs_into_a_clean_venv_and_runs_a_tiny_scene(tmp_path):
    wheels, venv, src = tmp_path / "wheels", tmp_path / "venv", tmp_path / "src"
    # built from a copy: setuptools writes build/ and *.egg-info beside the sources
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "runs", "docs", "build", "*.egg-info",
                                                             "__pycache__", ".pytest_cache"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(wheels), str(src)],
                   check=True, timeout=600)
    wheel = next(wheels.glob("gouge-*.whl"))
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", "-c", str(ROOT / "constraints.txt"),
                    str(wheel)], check=True, timeout=1800)
    scene = tmp_path / "tiny.yaml"
    scene.write_text(yaml.safe_dump({"name": "tiny", "seed": 4, "packing": {"n_grains": 200, "width": 12},
                                     "numerics": {"threads": 1}, "run": {"duration": 2000},
                                     "output": {"snapshot_interval": 1000}}))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "GOUGE_TEST_SEED_OFFSET")}
    proc = subprocess.run([str(venv / "bin" / "gouge"), "run", str(scene), "--out", str(tmp_path / "run"), "--quiet"],
                          cwd=tmp_path, capture_output=True, text=True, env=env, timeout=1200)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    check = subprocess.run([str(venv / "bin" / "python"), "-c",
                            "import gouge_cli as gouge, sys; r = gouge.open_run(sys.argv[1]); print(r.status, r.path)",
                            str(tmp_path / "run")], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert check.returncode == 0 and check.stdout.startswith("finished"), check.stdout + check.stderr
    assert str(ROOT) not in check.stdout
