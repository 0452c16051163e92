"""The LAMMPS deck of `gouge bench` is in the repository, and when LAMMPS cannot be timed the bench
says why instead of leaving its rows out silently."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from gouge_cli.studies import bench_lammps as bench

ROOT = Path(__file__).resolve().parents[2]
DECK = ROOT / "benchmarks" / "lammps"


def test_the_deck_is_found_in_the_repository(monkeypatch):
    monkeypatch.delenv("GOUGE_LAMMPS_BENCH", raising=False)
    assert bench.lammps_script() == DECK / "run.sh"
    for name in ("make_layer.py", "contacts.lmp", "walls.lmp", "prepare.lmp", "timed.lmp"):
        assert (DECK / name).is_file(), name


def test_make_layer_writes_exactly_n_atoms_in_the_bench_width(tmp_path):
    for n in (2500, 10000):
        data = tmp_path / f"layer{n}.data"
        subprocess.run([sys.executable, str(DECK / "make_layer.py"), str(n), str(data)], check=True,
                       capture_output=True)
        lines = data.read_text().splitlines()
        assert f"{n} atoms" in lines
        width = float(next(line for line in lines if line.endswith("xlo xhi")).split()[1])
        assert width == round(200 * (n / 1e4) ** 0.5)
        atoms = [line.split() for line in lines[lines.index("Atoms # sphere") + 2:] if line.strip()]
        assert len(atoms) == n
        kinds = [int(a[1]) for a in atoms]
        assert kinds.count(2) == kinds.count(3) == width          # one row of wall grains each side
        assert all(0.8 <= float(a[2]) <= 1.2 for a in atoms)


def test_missing_lmp_is_reported_with_how_to_install(monkeypatch):
    monkeypatch.setattr(bench.shutil, "which", lambda name: None)
    rate, reason = bench.time_lammps(2500, 1, 10, 0.89, 0.2, "granular")
    assert rate is None
    assert "lmp is not on PATH" in reason and "apt-get install lammps" in reason


def test_a_failing_lammps_is_reported_with_its_exit_code(tmp_path, monkeypatch):
    fake = tmp_path / "lmp"
    fake.write_text("#!/bin/sh\necho 'ERROR: Unrecognized pair style granular' >&2\nexit 1\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{tmp_path}{os.pathsep}{os.environ['PATH']}")
    rate, reason = bench.time_lammps(500, 1, 10, 0.89, 0.2, "granular")
    assert rate is None
    assert reason.startswith("LAMMPS failed (exit ") and "Unrecognized pair style" in reason


@pytest.mark.skipif(shutil.which("lmp") is None, reason="lmp is not installed (Debian/Ubuntu: apt-get install lammps)")
def test_a_real_lammps_times_the_deck():
    """With LAMMPS installed, the deck runs and gives a rate for both contact styles (a small
    layer, few steps: what is checked is that the rows exist, not their speed)."""
    for style in ("granular", "hh"):
        rate, reason = bench.time_lammps(500, 1, 200, 0.89, 0.2, style)
        assert reason is None and rate is not None and rate > 0, (style, reason)
