"""The README's five-minute tour and its Python block run verbatim (issue 60): each command line
of the tour's shell block in a fresh folder holding the repository's configs, then the Python block
in one process; every command exits 0 and prints no error. Validation-marked: it runs the demo and
two wet forks (about four minutes of one core)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.validation


def _blocks() -> tuple[list[str], str]:
    text = (ROOT / "README.md").read_text()
    tour = text.split("## A five-minute tour", 1)[1]
    shell = re.search(r"```\n(.*?)```", tour, re.S).group(1)
    python = re.search(r"```python\n(.*?)```", tour, re.S).group(1)
    lines = [line.split("#", 1)[0].strip() for line in shell.splitlines()]
    return [line for line in lines if line], python


def test_readme_tour_runs_as_printed(tmp_path):
    shutil.copytree(ROOT / "configs", tmp_path / "configs")
    gouge = str(Path(sys.executable).with_name("gouge"))
    commands, python = _blocks()
    assert commands[0].startswith("gouge run configs/demo.yaml") and len(commands) >= 5
    env = dict(os.environ, MPLBACKEND="Agg")
    for line in commands:
        args = line.split()
        done = subprocess.run([gouge, *args[1:]], cwd=tmp_path, env=env, capture_output=True, text=True)
        said = done.stdout + done.stderr
        assert done.returncode == 0 and "error" not in said.lower(), (line, said[-2000:])
    done = subprocess.run([sys.executable, "-c", "import matplotlib; matplotlib.use('Agg')\n" + python],
                          cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "error" not in (done.stdout + done.stderr).lower()
