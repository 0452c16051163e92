"""The run -> slips -> restart/resume workflow through the CLI, and its bit-for-bit identities."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.errors import CheckpointError, ConfigError
from gouge_cli.io.checkpoint import DIGEST_PREFIX, read_checkpoint, snapshot_of, write_checkpoint
from gouge_cli.io.integrity import content_digest
from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.io.runfile import SERIES_CHUNK
from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.io.verify import verify_run
from gouge_cli.workflows.fork import ForkRequest, run_fork
from gouge_cli.driver.simulation import Simulation
from slipping import slipping_run
from factories import branch_at, fork_at, scene

SCENE = scene("tiny", 4, run={"duration": 80000},
              output={"series_interval": 10, "snapshot_interval": 20000, "checkpoint_interval": 5000})
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny scene run to its end with 2 or more slips kept with checkpoints and a stress drop
    above 0.02: (config file, run directory, those slips' numbers)."""
    return slipping_run(SCENE, tmp_path_factory.mktemp("runs"), slips=2, min_drop=0.02)


@pytest.fixture(scope="module")
def scene_file(tiny):
    return tiny[0]


@pytest.fixture(scope="module")
def finished_run(tiny):
    return tiny[1]


def series(path: Path) -> dict:
    with h5py.File(path, "r") as h5:
        return {k: v[...] for k, v in h5["series"].items()}


def test_run_outputs_describe_themselves(finished_run):
    with h5py.File(finished_run / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished" and bool(h5.attrs["compaction_settled"])
        assert "normal_stress" in h5.attrs["config"] and "time_s" in h5.attrs["scales"]
        assert h5["series/tau_over_sigma"].attrs["unit"] == "1"          # pint's dimensionless
        assert h5["series/time"].shape[0] > 7000
        assert len(h5["snapshots"]) >= 4
        snap = h5["snapshots"][sorted(h5["snapshots"])[-1]]
        assert snap["contact_fx"].shape == snap["contact_i"].shape and snap["contact_i"].shape[0] > 300
    assert (finished_run / "config.yaml").is_file()


def test_catalog_has_slips_with_checkpoints(finished_run):
    catalog = slip_catalog(finished_run)
    kept = [e for e in catalog if e.checkpoint]
    assert len([e for e in kept if e.stress_drop > 0.02]) >= 2
    previous_end = -np.inf
    for e in catalog:
        assert e.end_time > e.onset_time and e.peak_velocity >= 10 * SCENE["loading"]["velocity"]
        if e.checkpoint:
            assert previous_end < e.checkpoint_time < e.onset_time   # after the last slip, before this
            assert (finished_run / e.checkpoint).is_file()
        previous_end = e.end_time
    listed = gouge("slips", finished_run, "--json")
    assert listed.exit_code == 0 and f'"number": {len(catalog)}' in listed.output


def test_checkpoint_restart_is_bitwise(tiny):
    """N steps + checkpoint + N steps == 2N steps, bit for bit (dry)."""
    _, finished_run, kept = tiny
    ck = read_checkpoint(finished_run / "checkpoints" / f"slip_{kept[1]:03d}.h5")
    steps = 4000
    while True:                 # long enough to cross list rebuilds (a stuck layer rebuilds rarely)
        straight = Simulation(ck.config, arrays=ck.state)
        straight.advance(steps)
        if straight.state.counters[1] > ck.state["counters"][1] + 1 or steps >= 64000:
            break
        steps *= 2
    halfway = Simulation(ck.config, arrays=ck.state)
    halfway.advance(steps // 2)
    path = finished_run / "mid.h5"
    write_checkpoint(path, snapshot_of(halfway))
    again = read_checkpoint(path)
    resumed = Simulation(again.config, arrays=again.state)
    resumed.advance(steps - steps // 2)
    a, b = straight.state.arrays(), resumed.state.arrays()
    assert a.keys() == b.keys()
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    assert a["counters"][1] > ck.state["counters"][1]   # rebuilds happened on the way


def test_drained_fork_retraces_the_original(tiny):
    _, finished_run, kept = tiny
    n = kept[1]
    summary = run_fork(ForkRequest(finished_run, n), quiet=True)
    drained = summary.branches["drained"]
    assert drained.status == "finished" and drained.first_slip is not None
    original = series(finished_run / "run.h5")
    fork = series(branch_at(finished_run, n).run_file)
    idx = np.searchsorted(original["time"], fork["time"][1:])
    assert np.array_equal(original["time"][idx], fork["time"][1:])
    for name in ("wall_x", "wall_vx", "tau_over_sigma", "porosity", "kinetic_energy", "max_overlap"):
        assert np.array_equal(original[name][idx], fork[name][1:]), name
    entry = next(e for e in slip_catalog(finished_run) if e.number == n)
    with h5py.File(finished_run / "run.h5", "r") as h5:          # restart reports times since loading began
        origin = float(h5["series/time"][0] - h5["series/load_time"][0])
    assert drained.first_slip.onset_time == pytest.approx(entry.onset_time - origin, abs=1e-9)
    # the fork wrote dense snapshots while its wall slipped (output.slip_frames, 30 by default)
    with h5py.File(branch_at(finished_run, n).run_file, "r") as h5:
        interval, dt = h5.attrs["snapshot_dense_interval"], h5.attrs["dt"]
        lo = yaml.safe_load(h5.attrs["config"])["slips"]["end_factor"] * SCENE["loading"]["velocity"]
        snaps = [h5["snapshots"][n] for n in sorted(h5["snapshots"])]
        sliding = [g for g in snaps if g["vx"][g["body"][...] == 2].mean() >= lo]
        dense = max(1, int(round(interval / dt)))       # on that step grid; a regular snapshot may fall between
        gaps = np.diff([g.attrs["time"] for g in sliding if g.attrs["step"] % dense == 0])
        assert gaps.size >= 2 and gaps.min() >= interval - dt
    again = gouge("restart", finished_run, "--slip", n)        # the drained branch alone again: --force
    assert again.exit_code == EXIT_BAD_INPUT and "--force" in again.output


@pytest.mark.parametrize("args,words", [
    (["--slip", 99, "--perm", "1e-5"], ["no checkpoint for slip 99", "KEPT"]),
    (["--slip", "N", "--perm", "-1e-5"], ["--perm", "positive"]),
    (["--slip", "N", "--perm", "1e-5", "--duration", "-5"], ["--duration"]),
    (["--slip", "N", "--perm", "1e-5", "--duration", "1e308"], ["--duration", "at most"]),     # OverflowError before
    (["--slip", "N", "--perm", "1e-5", "--duration", "1e30"], ["--duration", "at most"]),      # ran without bound
])
def test_restart_bad_input(tiny, args, words):
    """N: a slip kept with its checkpoint; KEPT: the list of those the message offers."""
    _, finished_run, kept = tiny
    offered = ", ".join(str(e.number) for e in slip_catalog(finished_run) if e.checkpoint)
    result = gouge("restart", finished_run, *[kept[1] if a == "N" else a for a in args])
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    for w in words:
        assert (offered if w == "KEPT" else w) in result.output


def test_restart_refuses_non_run_and_corrupt_checkpoint(tiny, tmp_path):
    _, finished_run, kept = tiny
    n = kept[0]
    result = gouge("restart", tmp_path, "--slip", n, "--perm", "1e-5")
    assert result.exit_code == EXIT_BAD_INPUT and "not a gouge run directory" in result.output
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-r", str(finished_run), str(copy)], check=True)
    ck = copy / "checkpoints" / f"slip_{n:03d}.h5"
    with h5py.File(ck, "r+") as h5:
        h5["state/x"][3] += 1e-9
    result = gouge("restart", copy, "--slip", n, "--perm", "1e-5")
    assert result.exit_code == EXIT_BAD_INPUT and "corrupt" in result.output
    ck.write_bytes(ck.read_bytes()[:5000])
    with pytest.raises(CheckpointError, match="unreadable or truncated"):
        read_checkpoint(ck)
    assert not fork_at(copy, n).root.exists()


def test_bad_config_writes_nothing(scene_file, tmp_path):
    out = tmp_path / "never"
    result = gouge("run", scene_file, "--out", out, "--set", "loading.velocity=-1", "--set", "packing.n_grain=3")
    assert result.exit_code == EXIT_BAD_INPUT
    assert "loading.velocity" in result.output and "packing.n_grain: unknown key" in result.output
    assert not out.exists()


WRITER = """
import sys, numpy as np
from gouge_cli.io.checkpoint import Checkpoint, CheckpointHeader, write_checkpoint
from gouge_cli.config import build_config
cfg = build_config({})
i = 0
while True:
    i += 1
    write_checkpoint(sys.argv[1], Checkpoint(cfg, {"x": np.full(3_000_000, float(i))}, {}, CheckpointHeader(slips=i)))
"""


def test_killed_writer_leaves_a_valid_checkpoint(tmp_path):
    path = tmp_path / "latest.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)])
    try:
        deadline = time.time() + 60
        while not path.exists() and time.time() < deadline:
            time.sleep(0.05)
        time.sleep(0.7)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    ck = read_checkpoint(path)           # verifies the checksum
    assert np.all(ck.state["x"] == ck.header.slips)


@pytest.fixture(scope="module")
def killed_run(scene_file, tmp_path_factory):
    """The tiny scene killed (SIGKILL) after its first checkpoint past t = 30000 t0 whose series
    end inside a chunk (the rows a later flush rewrites): its directory, as the kill left it (tests
    copy it)."""
    out = tmp_path_factory.mktemp("kill") / "killed"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "gouge_cli.cli", "run", str(scene_file), "--out", str(out), "--quiet"], env=env)
    latest = out / "checkpoints" / "latest.h5"
    try:
        deadline = time.time() + 120
        while time.time() < deadline and proc.poll() is None:
            if latest.exists():
                ck = read_checkpoint(latest)
                if ck.time > 30000 and ck.header.series_tail.rows % SERIES_CHUNK:
                    break
            time.sleep(0.1)
        assert proc.poll() is None, "the run finished before it could be killed"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    with h5py.File(out / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "running"
    return out


def _copy_of(run: Path, tmp_path: Path) -> Path:
    out = tmp_path / run.name
    shutil.copytree(run, out)
    return out


def _assert_matches_uninterrupted(finished_run: Path, out: Path):
    a = read_checkpoint(finished_run / "checkpoints" / "latest.h5").state
    b = read_checkpoint(out / "checkpoints" / "latest.h5").state
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    sa, sb = series(finished_run / "run.h5"), series(out / "run.h5")
    assert np.array_equal(sa["time"], sb["time"])        # no duplicated or missing rows
    assert np.array_equal(sa["wall_vx"], sb["wall_vx"])
    ca, cb = slip_catalog(finished_run), slip_catalog(out)
    assert [e.onset_time for e in ca] == [e.onset_time for e in cb]


def test_resume_after_kill_9_matches_uninterrupted(killed_run, finished_run, tmp_path):
    out = _copy_of(killed_run, tmp_path)
    result = gouge("resume", out, "--quiet")
    assert result.exit_code == 0, result.output
    _assert_matches_uninterrupted(finished_run, out)


def _tail_chunk(run: Path, column: str):
    """(SeriesTail of latest.h5, byte offset of `column`'s chunk holding the tail rows in run.h5)."""
    tail = read_checkpoint(run / "checkpoints" / "latest.h5").header.series_tail
    assert tail is not None and tail.rows % SERIES_CHUNK, tail      # (killed_run)
    with h5py.File(run / "run.h5", "r") as h5:
        return tail, h5["series"][column].id.get_chunk_info_by_coord((tail.start,)).byte_offset


def _overwrite(path: Path, offset: int, data: bytes):
    with open(path, "r+b") as f:
        f.seek(offset)
        f.write(data)


def test_resume_mends_the_chunk_a_kill_tore(killed_run, finished_run, tmp_path):
    """A kill inside a flush after the checkpoint can leave the last chunk's new rows under its old
    Fletcher-32 (a torn write: seen 1 in ~400 random kills of a writer, and once in the suite),
    so the rows before the checkpoint in that chunk fail their check though intact. Made here as
    the kernel leaves it: bytes after the checkpoint's rows changed, the checksum not. The resume
    mends it against the checkpoint's digest of those rows and matches the uninterrupted run."""
    out = _copy_of(killed_run, tmp_path)
    for column in ("wall_z", "wall_shear_stress"):
        tail, offset = _tail_chunk(out, column)
        _overwrite(out / "run.h5", offset + 8 * (tail.rows - tail.start), np.float64(1234.5).tobytes())
    with h5py.File(out / "run.h5", "r") as h5, pytest.raises(OSError):
        h5["series/wall_z"][tail.start:tail.rows]
    report = verify_run(out)
    problems = {p["object"]: p["recompute"] for f in report["files"] for p in f.get("problems", [])}
    assert set(problems) == {"/series/wall_z", "/series/wall_shear_stress"}, problems
    assert all(r.startswith(f"`gouge resume {out}`, which mends it") for r in problems.values()), problems
    result = gouge("resume", out, "--quiet")
    assert result.exit_code == 0, result.output
    assert "mended the series' last chunk in 2 column(s) (wall_shear_stress, wall_z)" in result.output
    _assert_matches_uninterrupted(finished_run, out)


def test_resume_refuses_a_tail_that_differs_from_the_checkpoint(killed_run, tmp_path):
    """A row before the checkpoint changed in that chunk (not a torn write: bit rot) does not match
    the checkpoint's digest: nothing is mended or resumed, and the file is left as it was."""
    out = _copy_of(killed_run, tmp_path)
    tail, offset = _tail_chunk(out, "wall_z")
    _overwrite(out / "run.h5", offset, np.float64(1234.5).tobytes())
    before = (out / "run.h5").read_bytes()
    result = gouge("resume", out, "--quiet")
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert "damaged data before the checkpoint" in result.output and "/series/wall_z" in result.output
    assert (out / "run.h5").read_bytes() == before
    problems = [p for f in verify_run(out)["files"] for p in f.get("problems", [])]
    assert [p["object"] for p in problems] == ["/series/wall_z"] and "mends" not in problems[0]["recompute"]


def test_resume_rebuilds_a_file_whose_snapshot_after_the_checkpoint_cannot_be_opened(killed_run, finished_run,
                                                                                    tmp_path):
    """A kill inside the HDF5 flush that writes a snapshot can leave its link without a readable
    object header (seen once in 20 kills: 'addr overflow', the header past the end the file
    records); HDF5 cannot delete such a link. Made here by overwriting a new snapshot's header.
    verify names the resume; the resume rebuilds run.h5 from what it keeps and matches the
    uninterrupted run."""
    out = _copy_of(killed_run, tmp_path)
    name = f"/snapshots/{read_checkpoint(out / 'checkpoints' / 'latest.h5').step + 1:012d}"
    with h5py.File(out / "run.h5", "r+") as h5:
        group = h5.create_group(name)
        group.create_dataset("x", data=np.zeros(3))
        header = h5py.h5o.get_info(group.id).addr
    _overwrite(out / "run.h5", header, b"\xff" * 16)
    with h5py.File(out / "run.h5", "r+") as h5, pytest.raises((KeyError, OSError, RuntimeError)):
        del h5[name]
    problems = [p for f in verify_run(out)["files"] for p in f.get("problems", [])]
    assert [p["object"] for p in problems] == [name], problems
    assert problems[0]["recompute"].startswith(f"`gouge resume {out}`, which drops it"), problems
    result = gouge("resume", out, "--quiet")
    assert result.exit_code == 0, result.output
    assert "rebuilt" in result.output
    _assert_matches_uninterrupted(finished_run, out)
    assert verify_run(out)["sound"]
    assert not list(out.glob(".*tmp*"))


def test_run_file_and_checkpoints_record_provenance(finished_run):
    """Version, commit, command, library versions, CPU and threads in run.h5 and every checkpoint;
    the final state's hash in run.h5."""
    import json
    import re

    import numba

    from gouge_cli.io import provenance
    with h5py.File(finished_run / "run.h5", "r") as h5:
        prov = json.loads(h5.attrs["provenance"])
        final_hash = h5.attrs["final_state_hash"]
    assert re.fullmatch(r"[0-9a-f]{16}", final_hash)
    assert prov["gouge_version"] and (re.fullmatch(r"[0-9a-f]{40}(\+dirty)?", prov["git_commit"])
                                      or prov["git_commit"] == "not a git checkout")
    assert isinstance(prov["command"], list) and prov["command"]
    libs = prov["libraries"]
    assert libs["numpy"] == np.__version__ and libs["numba"] == numba.__version__ and libs["h5py"] == h5py.__version__
    assert {"python", "llvmlite", "libc"} <= set(libs)
    assert prov["cpu"]["model"] and isinstance(prov["cpu"]["vector_features"], list)
    assert prov["cpu"]["vector_width_bits"] in (128, 256, 512) and prov["threads"] >= 1
    for path in [finished_run / "checkpoints" / "latest.h5"] + sorted((finished_run / "checkpoints").glob("slip_*.h5")):
        ck = read_checkpoint(path)
        assert ck.provenance["libraries"] == libs and ck.provenance["threads"] >= 1, path
        assert provenance.bit_risks(ck.provenance) == []


def test_moved_run_directory_still_forks(finished_run, tmp_path):
    """Stored paths are relative: a run directory copied elsewhere forks from its own checkpoints,
    and the branch's parent_run points back at the moved run."""
    import re
    import shutil
    moved = tmp_path / "elsewhere" / "tiny"
    shutil.copytree(finished_run, moved, ignore=shutil.ignore_patterns("forks"))
    slip = next(e.number for e in slip_catalog(moved) if e.checkpoint)
    summary = run_fork(ForkRequest(moved, slip, duration=100.0), quiet=True)
    branch = branch_at(moved, slip).root
    with h5py.File(branch / "run.h5", "r") as h5:
        assert (branch / h5.attrs["parent_run"]).resolve() == moved.resolve()
        assert re.fullmatch(r"[0-9a-f]{16}", h5.attrs["final_state_hash"])
    assert (branch.parent / summary.run).resolve() == moved.resolve()
    assert summary.branches["drained"].dir == "drained" and summary.library_differences_from_parent == []


def test_restart_names_library_differences_from_the_parent(finished_run, tmp_path):
    """A checkpoint written with another numpy: restart says so in one line before running and
    pair.json records it; the fork still runs."""
    import json
    import shutil
    run = tmp_path / "other_numpy"
    shutil.copytree(finished_run, run, ignore=shutil.ignore_patterns("forks"))
    slip = next(e.number for e in slip_catalog(run) if e.checkpoint)
    path = run / "checkpoints" / f"slip_{slip:03d}.h5"
    with h5py.File(path, "r+") as h5:
        prov = json.loads(h5.attrs["provenance"])
        prov["libraries"]["numpy"] = "1.0.0"
        h5.attrs["provenance"] = json.dumps(prov)
        h5.attrs["checksum"] = DIGEST_PREFIX + content_digest(h5)     # an edited checkpoint, stamped again
    result = gouge("restart", run, "--slip", slip, "--perm", "1e-5", "--duration", "50", "--quiet")
    assert result.exit_code == 0, result.output
    assert f"numpy 1.0.0 -> {np.__version__}" in result.output
    pair = json.loads(fork_at(run, slip).pair_file.read_text())
    assert pair["library_differences_from_parent"] == [f"numpy 1.0.0 -> {np.__version__}"]


def test_a_fork_request_is_checked_when_built(tmp_path):
    request = ForkRequest(tmp_path, 3, [1e-5], {"output.slip_frames": 12}, 40.0)
    assert request.perms == (1e-5,)
    assert request.command().endswith("--slip 3 --perm 1e-05 --set output.slip_frames=12 --duration 40")
    for bad, key in (({"perms": [-1.0]}, "--perm"), ({"duration": float("inf")}, "--duration"),
                     ({"main": "last"}, "--main")):
        with pytest.raises(ConfigError, match=key):
            ForkRequest(tmp_path, 3, **bad)
