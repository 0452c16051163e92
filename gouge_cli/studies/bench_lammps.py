"""LAMMPS's side of `gouge bench`: the deck in ``benchmarks/lammps`` timed on the same scene,
or why it cannot be timed here."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

LAMMPS_INSTALL = "apt-get install lammps (and openmpi-bin for 2+ ranks); or build LAMMPS with its GRANULAR package"


def lammps_script() -> Path | None:
    """The deck's driver: $GOUGE_LAMMPS_BENCH, else benchmarks/lammps/run.sh of this checkout."""
    candidates = [os.environ.get("GOUGE_LAMMPS_BENCH", ""),
                  Path(__file__).resolve().parents[2] / "benchmarks" / "lammps" / "run.sh"]
    for c in candidates:
        if c and Path(c).is_file():
            return Path(c)
    return None


def lammps_missing(ranks: int = 1) -> str | None:
    """Why LAMMPS cannot be timed here (None when it can): no deck, no `lmp`, no `mpirun`."""
    if lammps_script() is None:
        return ("the LAMMPS deck benchmarks/lammps/run.sh is not in this installation "
                "(run from a checkout, or set GOUGE_LAMMPS_BENCH to its path)")
    if shutil.which("lmp") is None:
        return f"lmp is not on PATH: {LAMMPS_INSTALL}"
    if ranks > 1 and shutil.which("mpirun") is None:
        return f"mpirun is not on PATH (needed for {ranks} ranks): apt-get install openmpi-bin"
    return None


def time_lammps(n_grains: int, ranks: int, steps: int, dt: float, skin: float,
                style: str) -> tuple[float | None, str | None]:
    """(grain-steps per second, None), or (None, why LAMMPS gave no rate)."""
    reason = lammps_missing(ranks)
    if reason:
        return None, reason
    try:
        proc = subprocess.run(["bash", str(lammps_script()), str(n_grains), str(ranks), str(steps), str(dt),
                               str(skin), style], capture_output=True, text=True, timeout=1800)
    except subprocess.TimeoutExpired:
        return None, "LAMMPS took more than 30 minutes"
    match = re.search(r"grain_steps_per_s=([\d.eE+-]+)", proc.stdout)
    if match:
        return float(match.group(1)), None
    lines = [line.strip() for line in (proc.stderr + "\n" + proc.stdout).splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("ERROR")]       # LAMMPS's own, before mpirun's
    shown = errors[:2] or lines[-3:]
    return None, f"LAMMPS failed (exit {proc.returncode}): {' | '.join(shown) or 'no output'}"
