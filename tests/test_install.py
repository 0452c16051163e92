"""How gouge installs: `make demo` takes the runtime dependencies only (the extras come with
`make test` and `make docs`); a plain `pip install .` (no extras, not editable) gives a working
`gouge`; a wheel built from the checkout installs into a clean virtual environment and runs a tiny
scene. The last two are slow and run only where asked: GOUGE_WHEEL_TEST=1 (.ci/run sets it)."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
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


slow_install = pytest.mark.skipif(os.environ.get("GOUGE_WHEEL_TEST") != "1",
                                  reason="installs gouge into a fresh venv (minutes): CI sets GOUGE_WHEEL_TEST=1")


def _source_copy(tmp_path: Path) -> Path:
    """The checkout's sources copied (setuptools writes build/ and *.egg-info beside them)."""
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "runs", "docs", "build", "*.egg-info",
                                                             "__pycache__", ".pytest_cache"))
    return src


def _builds_offline() -> bool:
    """Whether this environment's setuptools builds a wheel with no network (setuptools >= 70.1, or wheel)."""
    for module in ("setuptools.command.bdist_wheel", "wheel.bdist_wheel"):
        try:
            if importlib.util.find_spec(module) is not None:
                return True
        except ImportError:          # its parent package is missing
            pass
    return False


@slow_install
def test_pip_install_of_the_checkout_runs_gouge(tmp_path):
    """`pip install .` into a fresh venv (without pip; the dependencies seen from this environment, so that
    no package is downloaded): `gouge --help` and `gouge config` run from the installed copy. Offline
    (--no-index --no-build-isolation) where this environment's setuptools can build a wheel."""
    src, venv = _source_copy(tmp_path), tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    python = str(venv / "bin" / "python")
    site = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    stdlib = Path(sysconfig.get_paths()["stdlib"]).resolve()           # the venv has its own; pip's build env drops these
    outer = [p for p in sys.path if p and Path(p).is_dir()
             and not any(Path(p).resolve().is_relative_to(skip) for skip in (ROOT, stdlib))]    # nor the checkout
    Path(site, "_gouge_test_deps.pth").write_text("".join(f"{p}\n" for p in outer))
    offline = ["--no-index", "--no-build-isolation"] if _builds_offline() else []
    subprocess.run([sys.executable, "-m", "pip", "--python", python, "install", "--quiet", *offline, str(src)],
                   check=True, timeout=900)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "GOUGE_TEST_SEED_OFFSET")}
    where = subprocess.run([python, "-c", "import gouge_cli; print(gouge_cli.__file__)"], cwd=tmp_path,
                           capture_output=True, text=True, env=env, check=True).stdout
    assert where.startswith(site), where                       # the installed copy, not the checkout
    shown = subprocess.run([str(venv / "bin" / "gouge"), "--help"], cwd=tmp_path, capture_output=True, text=True,
                           env=env, timeout=300)
    assert shown.returncode == 0 and "config" in shown.stdout, shown.stdout + shown.stderr
    config = subprocess.run([str(venv / "bin" / "gouge"), "config"], cwd=tmp_path, capture_output=True, text=True,
                            env=env, timeout=300)
    assert config.returncode == 0 and yaml.safe_load(config.stdout)["scales"]["length_m"] > 0, config.stderr


@slow_install
def test_wheel_installs_into_a_clean_venv_and_runs_a_tiny_scene(tmp_path):
    wheels, venv, src = tmp_path / "wheels", tmp_path / "venv", _source_copy(tmp_path)
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
    # the named scenes travel with the wheel (issue 60: "scene names are looked up in .../site-packages/configs")
    demo = subprocess.run([str(venv / "bin" / "gouge"), "run", "demo", "--set", "run.duration=20000", "--out",
                           str(tmp_path / "demo"), "--quiet"], cwd=tmp_path, capture_output=True, text=True, env=env,
                          timeout=1200)
    assert demo.returncode == 0, demo.stdout + demo.stderr
