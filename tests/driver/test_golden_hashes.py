"""Golden state hashes: the bits of the reference scenes (gouge_cli.studies.reference) and of the demo.

"Same bits" is a claim about absolute values, not only about two runs agreeing: a change that moved
every build's bits the same way would pass test_reproducibility. These tests pin the final state
hash of each reference scene on 1 and 2 threads (default suite) and the demo's final_state_hash and
slip count (validation suite). They run in fresh processes with the seed offset switched off
(GOUGE_TEST_SEED_OFFSET shifts every packing's seed; these scenes are fixed by definition), with
the host's code and with numba's baseline x86-64 target (NUMBA_CPU_NAME=generic: no AVX, no FMA).

A change that is meant to alter the bits (new physics, another summation order) updates the values
here in the same commit, and says why in the commit message and in CHANGELOG.md.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import h5py
import numba
import pytest

from gouge_cli.io.slipcatalog import slip_catalog
from needs import two_threads

REPO = Path(__file__).resolve().parents[2]

GOLDEN = {"dry": "e9db53e39dbb39ad", "undrained": "1fb8cb4453300786", "undrained-heun": "01e3d2fd4b2c9a7d"}
DEMO_HASH, DEMO_SLIPS = "330891096953c867", 5


def _env(threads: int, generic: bool = False) -> dict:
    """The environment of a fresh gouge process: no seed offset, `threads` numba threads, host or
    baseline code generation."""
    env = {k: v for k, v in os.environ.items() if k not in ("GOUGE_TEST_SEED_OFFSET", "NUMBA_CPU_NAME",
                                                             "NUMBA_CPU_FEATURES")}
    env["NUMBA_NUM_THREADS"] = str(threads)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    if generic:
        env["NUMBA_CPU_NAME"] = "generic"
    return env


def _reference(threads: int, generic: bool = False) -> dict:
    out = subprocess.run([sys.executable, "-m", "gouge_cli.studies.reference", "--json", "--threads", str(threads)],
                         env=_env(threads, generic), capture_output=True, text=True, timeout=1800, cwd=REPO)
    assert out.returncode == 0, out.stderr[-3000:]
    rows = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    return {row["scene"]: row for row in rows}


def _check(rows: dict):
    assert sorted(rows) == sorted(GOLDEN)
    assert rows["dry"]["updates"] == 0
    assert rows["undrained"]["updates"] > 0 and rows["undrained"]["explicit_updates"] == 0       # auto: implicit
    assert rows["undrained-heun"]["explicit_updates"] == rows["undrained-heun"]["updates"] > 0   # auto: Heun
    assert {kind: row["hash"] for kind, row in rows.items()} == GOLDEN


@pytest.mark.parametrize("threads", [1, pytest.param(2, marks=two_threads)])
def test_reference_scenes_keep_their_hashes(threads):
    _check(_reference(threads))


@pytest.mark.validation
@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="NUMBA_CPU_NAME=generic is x86-64 only")
@pytest.mark.parametrize("threads", [1, pytest.param(2, marks=two_threads)])
def test_reference_scenes_keep_their_hashes_with_baseline_code(threads):
    _check(_reference(threads, generic=True))


@pytest.mark.validation
def test_demo_keeps_its_hash_and_slips(tmp_path):
    """`make demo` (configs/demo.yaml): 5 slips and final_state_hash 330891096953c867."""
    out = tmp_path / "demo"
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    proc = subprocess.run([sys.executable, "-m", "gouge_cli.cli", "run", str(REPO / "configs" / "demo.yaml"),
                           "--out", str(out), "--quiet"], env=_env(threads), capture_output=True, text=True,
                          timeout=3600, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with h5py.File(out / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished"
        final = h5.attrs["final_state_hash"]
    assert (final, len(slip_catalog(out))) == (DEMO_HASH, DEMO_SLIPS)
    # the demo shows the thesis's block slider: at least half of its slips follow Eq. 3
    proc = subprocess.run([sys.executable, "-m", "gouge_cli.cli", "analyze", str(out)],
                          env=_env(threads), capture_output=True, text=True, timeout=600, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    import gouge_cli.api as gouge

    verdicts = list(gouge.open_run(out).slips["fit_verdict"])
    assert sum(v == "holds" for v in verdicts) >= len(verdicts) / 2, verdicts
