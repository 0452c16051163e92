"""No corrupted byte is used silently (issue 42): single-bit flips planted in the stored bytes of
datasets and attributes of a checkpoint, latest.h5, run.h5 and a fork's run.h5 (sampled, seeded)
are each found by `gouge verify`, refused with exit 2 by the commands that read them, or shown to
change nothing they output; the run file's time series is checked increasing; resume and
restart compute nothing from a damaged file.

One run of the 300-grain kill scene (one slip with its checkpoint) and one drained fork of
that slip are built per module; each flip is planted in place and undone afterwards.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import re
import shutil
import struct
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import CheckpointError, DamagedFileError, MAX_MESSAGE
from gouge_cli.io import provenance
from gouge_cli.io.checkpoint import read_checkpoint
from gouge_cli.io.integrity import all_objects, seal, value_bytes
from gouge_cli.io.runreader import RunReader
from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.io.verify import run_file_problems, verify_run
from slipping import slipping_run
from factories import scene

SCENE = scene("flips", 4, numerics={"threads": 1}, run={"duration": 14000},
              output={"series_interval": 10, "snapshot_interval": 5000, "checkpoint_interval": 1000},
              slips={"start_factor": 4, "end_factor": 1.5})
SEED = 42 + int(os.environ.get("GOUGE_TEST_SEED_OFFSET", "0"))
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def refused(result, *words):
    """Exit 2 with a short message (no traceback) naming each of `words`."""
    assert result.exit_code == 2, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    text = result.output.strip()
    assert "Traceback" not in text and len(text) <= 3 * MAX_MESSAGE, text
    for w in words:
        assert w in text, (w, text)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A finished run with a slip kept with its checkpoint, and the drained fork of that slip."""
    _, out, slips = slipping_run(SCENE, tmp_path_factory.mktemp("integrity"), slips=1, grow=1.5)
    result = gouge("restart", out, "--slip", slips[0], "--set", "output.slip_frames=3", "--quiet")
    assert result.exit_code == 0, result.output
    return out, slips[0]


def interrupted_copy(run_dir: Path, target: Path, more: float = 300.0) -> Path:
    """A copy of the finished run that reads as killed `more` t0 before its end (status running,
    end_time later; the root's seal renewed as the writer does), so `gouge resume` continues it."""
    shutil.copytree(run_dir, target, ignore=shutil.ignore_patterns("forks"))
    with h5py.File(target / "run.h5", "r+") as h5:
        h5.attrs["status"] = "running"
        h5.attrs["end_time"] = float(h5.attrs["end_time"]) + more
        seal(h5)
    return target


def sha(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# planting flips ------------------------------------------------------------------------------

def dataset_spans(path: Path) -> list[tuple[str, int, int]]:
    """(dataset, byte offset, stored size) of every stored chunk or contiguous block."""
    spans = []

    def visit(name, obj):
        if not isinstance(obj, h5py.Dataset):
            return
        if obj.chunks:
            for i in range(obj.id.get_num_chunks()):
                info = obj.id.get_chunk_info(i)
                spans.append(("/" + name, info.byte_offset, info.size))
        else:
            offset, size = obj.id.get_offset(), obj.id.get_storage_size()
            if offset is not None and size:
                spans.append(("/" + name, offset, size))

    with h5py.File(path, "r") as h5:
        h5.visititems(visit)
    return spans


def attributes(path: Path) -> list[tuple[str, str]]:
    """(object, name) of every attribute whose stored value has a byte to flip (an empty string,
    such as a fork's slip without a checkpoint, has none)."""
    out = []
    with h5py.File(path, "r") as h5:
        for obj_path, obj in all_objects(h5).items():
            out += [(obj_path, name) for name, value in obj.attrs.items()
                    if (len(value) if isinstance(value, (str, bytes)) else np.asarray(value).nbytes)]
    return sorted(out)


def flip(path: Path, offset: int, bit: int):
    with open(path, "r+b") as f:
        f.seek(offset)
        byte = f.read(1)[0]
        f.seek(offset)
        f.write(bytes([byte ^ (1 << bit)]))


def _attr_bytes(path: Path, obj: str, name: str):
    try:
        with h5py.File(path, "r") as h5:
            return value_bytes(h5[obj].attrs[name])
    except Exception:          # noqa: BLE001 - an attribute made unreadable is a change too
        return None


def plant_in_attribute(path: Path, obj: str, name: str, rng: random.Random) -> tuple[int, int] | None:
    """Flip one bit of the stored value of attribute `name` of `obj` (found by its bytes in the
    file; of several occurrences, the one whose flip changes that attribute). Returns
    (offset, bit), or None if its bytes are not found."""
    with h5py.File(path, "r") as h5:
        value = h5[obj].attrs[name]
    raw = value.encode() if isinstance(value, str) else np.asarray(value).tobytes()
    if not raw:
        return None
    before = value_bytes(value)
    k, bit = rng.randrange(len(raw)), rng.randrange(8)
    data = Path(path).read_bytes()
    starts = []
    if isinstance(value, str):      # a string's global-heap object: its 8-byte length, then the bytes
        starts = [m.start() + 8 for m in re.finditer(re.escape(struct.pack("<Q", len(raw)) + raw), data)]
    starts += [m.start() for m in re.finditer(re.escape(raw), data) if m.start() not in starts]
    for start in starts[:2000]:
        flip(path, start + k, bit)
        if _attr_bytes(path, obj, name) != before:
            return start + k, bit
        flip(path, start + k, bit)
    return None


def plants(path: Path, rng: random.Random, datasets: int = 12, attrs: int = 12):
    """Seeded sample of flips: (what, offset, bit) for up to `datasets` stored blocks (one flip
    in each, every dataset first) and up to `attrs` attributes of the file."""
    spans = dataset_spans(path)
    by_name = {}
    for span in spans:
        by_name.setdefault(span[0], []).append(span)
    chosen = [rng.choice(v) for v in by_name.values()]
    rng.shuffle(chosen)
    for name, offset, size in chosen[:datasets]:
        yield f"dataset {name}", offset + rng.randrange(size), rng.randrange(8)
    names = attributes(path)
    for obj, name in rng.sample(names, min(attrs, len(names))):
        planted = plant_in_attribute(path, obj, name, rng)
        assert planted is not None, f"attribute {obj}:{name} not found in {path}"
        flip(path, *planted)                    # undone here, planted again by the caller
        yield f"attribute {obj}:{name}", *planted


# the tests -----------------------------------------------------------------------------------

def files_of(run_dir: Path, slip: int) -> dict[str, Path]:
    return {"run.h5": run_dir / "run.h5", f"checkpoints/slip_{slip:03d}.h5": run_dir / f"checkpoints/slip_{slip:03d}.h5",
            "checkpoints/latest.h5": run_dir / "checkpoints/latest.h5",
            f"forks/slip_{slip:03d}/drained/run.h5": run_dir / f"forks/slip_{slip:03d}/drained/run.h5"}


def test_a_sound_run_verifies(run):
    run_dir, slip = run
    result = gouge("verify", run_dir, "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["sound"] and {f["status"] for f in report["files"]} == {"sound"}
    assert {f["path"] for f in report["files"]} >= set(files_of(run_dir, slip))


def damaged(path: Path) -> bool:
    """What `gouge verify` finds in one file: a run file's problems, or a checkpoint refused."""
    if path.name == "run.h5":
        return bool(run_file_problems(path)[0])
    try:
        read_checkpoint(path)
    except CheckpointError as err:
        assert str(path) in str(err)
        return True
    return False


@pytest.mark.parametrize("which", ["run.h5", "checkpoint", "latest.h5", "fork"])
def test_every_planted_flip_is_found(run, which):
    """Each flip is found by the check `gouge verify` runs on its file (for a checkpoint, what
    restart and resume read through); every dataset is sampled first, then attributes."""
    run_dir, slip = run
    rel = {"run.h5": "run.h5", "checkpoint": f"checkpoints/slip_{slip:03d}.h5", "latest.h5": "checkpoints/latest.h5",
           "fork": f"forks/slip_{slip:03d}/drained/run.h5"}[which]
    path = run_dir / rel
    original = sha(path)
    assert not damaged(path)
    planted = list(plants(path, random.Random(f"{SEED}-{which}")))
    assert sum(w.startswith("attribute") for w, _, _ in planted) == 12 and len(planted) > 12
    missed = []
    for what, offset, bit in planted:
        flip(path, offset, bit)
        try:
            if not damaged(path):
                missed.append((what, offset, bit))
        finally:
            flip(path, offset, bit)
    assert sha(path) == original
    assert not missed, missed[:5]


def test_verify_reports_flips_in_every_file(run, tmp_path):
    """One flip planted in each file of a run (run.h5, a slip checkpoint, latest.h5, the fork):
    `gouge verify` exits 2 and reports each of those files, and only them, damaged."""
    run_dir, slip = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    rng = random.Random(f"{SEED}-verify")
    files = files_of(work, slip)
    for path in files.values():
        name, offset, size = rng.choice(dataset_spans(path))
        flip(path, offset + rng.randrange(size), rng.randrange(8))
    result = gouge("verify", work, "--json")
    assert result.exit_code == 2, result.output
    report = json.loads(result.output)
    assert not report["sound"]
    assert {f["path"] for f in report["files"] if f["status"] == "damaged"} == set(files)
    fork = next(f for f in report["files"] if f["kind"] == "fork")
    assert f"--slip {slip}" in fork["recompute"]
    text = gouge("verify", work)
    assert text.exit_code == 2 and text.output.count("damaged") >= 4


def test_run_file_flips_are_refused_or_change_nothing(run, tmp_path):
    """A sample of flips in run.h5 (and one in a series and one in a slip's onset_time, which
    they read): `gouge slips --json` and `gouge analyze --json` exit 2 naming run.h5, or print
    exactly what they print for the sound file."""
    run_dir, _ = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    reference = {cmd: gouge(cmd, work, "--json") for cmd in ("slips", "analyze")}
    assert all(r.exit_code == 0 for r in reference.values())
    reference = {cmd: r.output.replace(str(work), "RUN") for cmd, r in reference.items()}
    rng = random.Random(f"{SEED}-consumers")
    detected = harmless = 0
    planted = list(plants(work / "run.h5", rng, datasets=5, attrs=5))
    _, offset, size = next(x for x in dataset_spans(work / "run.h5") if x[0] == "/series/wall_vx")
    planted.append(("dataset /series/wall_vx", offset + rng.randrange(size), rng.randrange(8)))
    slip = slip_catalog(work)[0].number
    at = plant_in_attribute(work / "run.h5", f"/slips/{slip:03d}", "onset_time", rng)
    flip(work / "run.h5", *at)
    planted.append((f"attribute /slips/{slip:03d}:onset_time", *at))
    for what, offset, bit in planted:
        trial = tmp_path / f"trial{offset}_{bit}"
        shutil.copytree(work, trial)
        flip(trial / "run.h5", offset, bit)
        for cmd in ("slips", "analyze"):
            result = gouge(cmd, trial, "--json")
            if result.exit_code == 2:
                refused(result, "run.h5")
                detected += 1
            else:
                assert result.exit_code == 0, (what, result.output)
                assert result.output.replace(str(trial), "RUN") == reference[cmd], (what, cmd)
                harmless += 1
        shutil.rmtree(trial)
    assert detected >= 3 and detected + harmless == 2 * len(planted)     # wall_vx: analyze; onset_time: both


def _flip_text(path: Path, old: bytes, new: bytes):
    """Turn `old` into `new` (one bit apart) where it occurs in the file."""
    diff = [(i, a ^ b) for i, (a, b) in enumerate(zip(old, new)) if a != b]
    assert len(diff) == 1 and bin(diff[0][1]).count("1") == 1
    data = Path(path).read_bytes()
    at = data.index(old)
    flip(path, at + diff[0][0], diff[0][1].bit_length() - 1)


def test_config_flip_refused_by_restart_and_resume(run, tmp_path):
    """friction: 0.5 -> 1.5 (one bit) in a slip checkpoint and in latest.h5: restart and resume exit
    2 naming the checkpoint, and nothing is computed or written."""
    run_dir, slip = run
    work = tmp_path / "restart"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    ck = work / f"checkpoints/slip_{slip:03d}.h5"
    _flip_text(ck, b"friction: 0.5", b"friction: 1.5")
    with h5py.File(ck, "r") as h5:
        assert "friction: 1.5" in h5.attrs["config"]          # the flip reads as a valid config
    refused(gouge("restart", work, "--slip", slip, "--perm", 1e-5), ck.name, "corrupt")
    assert not (work / "forks").exists()

    stopped = interrupted_copy(run_dir, tmp_path / "resume")
    before = sha(stopped / "run.h5")
    _flip_text(stopped / "checkpoints/latest.h5", b"friction: 0.5", b"friction: 1.5")
    refused(gouge("resume", stopped, "--quiet"), "latest.h5", "corrupt")
    assert sha(stopped / "run.h5") == before


def test_unreadable_extra_attribute_is_exit_2(run, tmp_path):
    """A flip that makes `extra` invalid UTF-8 (its first byte '{' -> 0xfb): one line, exit 2."""
    run_dir, slip = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    ck = work / f"checkpoints/slip_{slip:03d}.h5"
    with h5py.File(ck, "r") as h5:
        extra = h5.attrs["extra"].encode()
    flip(ck, Path(ck).read_bytes().index(extra), 7)
    with pytest.raises(CheckpointError, match="slip_"):
        read_checkpoint(ck)
    refused(gouge("restart", work, "--slip", slip), ck.name)


def test_resume_of_a_sound_interrupted_copy_still_works(run, tmp_path):
    run_dir, _ = run
    stopped = interrupted_copy(run_dir, tmp_path / "resume")
    result = gouge("resume", stopped, "--quiet")
    assert result.exit_code == 0, result.output
    assert verify_run(stopped)["sound"]


def test_resume_refuses_a_damaged_chunk_before_its_checkpoint(run, tmp_path):
    run_dir, _ = run
    stopped = interrupted_copy(run_dir, tmp_path / "resume")
    name, offset, size = next(s for s in dataset_spans(stopped / "run.h5") if s[0] == "/series/wall_x")
    flip(stopped / "run.h5", offset + 8 * 7 + 2, 3)           # inside row 7, before the checkpoint's rows
    before = sha(stopped / "run.h5")
    refused(gouge("resume", stopped, "--quiet"), "series/wall_x", "rows", "nothing was resumed")
    assert sha(stopped / "run.h5") == before


def test_series_flip_names_dataset_and_rows(run, tmp_path):
    run_dir, _ = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    _, offset, size = next(s for s in dataset_spans(work / "run.h5") if s[0] == "/series/wall_vx")
    flip(work / "run.h5", offset + 8 * 7 + 2, 5)               # inside row 7's value
    result = gouge("analyze", work, "--json")
    refused(result, "series/wall_vx", "fail their checksum")
    assert re.search(r"rows \d+-\d+ \(of \d+\)", result.output)       # the rows it read, in the damaged chunk
    with RunReader(work) as reader:                           # the other series stay usable
        assert reader.series(["wall_x"])["wall_x"].size == reader.info.n_samples


def test_time_must_increase(run, tmp_path):
    """A time series that decreases (written with valid chunk checksums) is refused on opening."""
    run_dir, _ = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    with h5py.File(work / "run.h5", "r+") as h5:
        t = h5["series/time"]
        t[50] = t[10]
    with pytest.raises(DamagedFileError, match=r"series/time: row 50 "):
        RunReader(work)
    refused(gouge("analyze", work), "series/time", "row 50")
    report = verify_run(work)
    assert not report["sound"] and any(p["object"] == "/series/time" for p in report["files"][0]["problems"])


def test_slip_attribute_flip_refused_by_slips(run, tmp_path):
    run_dir, slip = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    planted = plant_in_attribute(work / "run.h5", f"/slips/{slip:03d}", "onset_time", random.Random(SEED))
    assert planted is not None
    refused(gouge("slips", work), f"/slips/{slip:03d}")
    refused(gouge("analyze", work), f"/slips/{slip:03d}")


def test_damaged_snapshot_refused_by_export_while_series_stay_usable(run, tmp_path):
    run_dir, _ = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    name, offset, size = next(s for s in dataset_spans(work / "run.h5") if s[0].startswith("/snapshots/")
                              and s[0].endswith("/x"))
    with open(work / "run.h5", "r+b") as f:
        f.seek(offset)
        f.write(b"\xff" * size)
    refused(gouge("export", work, "--out", tmp_path / "out.vtkhdf"), name)
    assert not (tmp_path / "out.vtkhdf").exists()
    assert gouge("analyze", work, "--json").exit_code == 0     # a damaged snapshot hides no series
    result = gouge("verify", work, "--json")
    assert result.exit_code == 2
    report = json.loads(result.output)
    problems = report["files"][0]["problems"]
    assert [p["object"] for p in problems] == [name] and problems[0]["part"] == "snapshot"
    assert "recompute" in problems[0]


def test_checkpoint_written_before_the_full_digest_is_still_read(run, tmp_path):
    """A checkpoint whose checksum is the old one (datasets only) reads as before."""
    run_dir, slip = run
    ck = tmp_path / "old.h5"
    shutil.copy(run_dir / f"checkpoints/slip_{slip:03d}.h5", ck)
    new = read_checkpoint(ck)
    with h5py.File(ck, "r+") as h5:
        groups = {g: {n: d[...] for n, d in h5[g].items()} for g in ("state", "fluid") if g in h5}
        for key in h5["attached"] if "attached" in h5 else []:
            for part in ("state", "fluid"):
                groups[f"attached/{key}/{part}"] = {n: d[...] for n, d in h5[f"attached/{key}/{part}"].items()}
        h5.attrs["checksum"] = provenance.state_digest(dict(groups, fluid=groups.get("fluid", {})))
    old = read_checkpoint(ck)
    assert all(np.array_equal(old.state[k], new.state[k]) for k in new.state)
    with h5py.File(ck, "r+") as h5:
        h5["state/x"][0] += 1e-12
    with pytest.raises(CheckpointError, match="corrupt"):
        read_checkpoint(ck)


def test_damaged_snapshot_refused_by_movie(run, tmp_path):
    """A snapshot chunk of a fork branch made unreadable: `gouge movie` exits 2 naming the branch
    file and the dataset, and leaves no movie behind."""
    run_dir, slip = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    result = gouge("restart", work, "--slip", slip, "--perm", 1e-4, "--set", "output.slip_frames=3", "--quiet")
    assert result.exit_code == 0, result.output
    movie = tmp_path / "slip.mp4"
    assert gouge("movie", work, "--slip", slip, "--out", tmp_path / "sound.gif").exit_code == 0
    branch = work / f"forks/slip_{slip:03d}/drained/run.h5"
    name, offset, size = next(s for s in dataset_spans(branch) if s[0].startswith("/snapshots/") and s[0].endswith("/x"))
    with open(branch, "r+b") as f:
        f.seek(offset)
        f.write(b"\xff" * size)
    refused(gouge("movie", work, "--slip", slip, "--out", movie), name, "drained")
    assert not movie.exists()


def test_campaign_status_read_through_the_seal(run, tmp_path):
    """The campaign decides to resume, restart or keep a point's run from its status attribute:
    read through the root seal, a flipped status is DamagedFileError, never a silent re-run."""
    from gouge_cli.io.runreader import run_status

    run_dir, _ = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work, ignore=shutil.ignore_patterns("forks"))
    assert run_status(work / "run.h5") == "finished"
    assert run_status(tmp_path / "missing.h5") is None
    _flip_text(work / "run.h5", b"finished", b"finishee")
    with pytest.raises(DamagedFileError, match="do not match"):
        run_status(work / "run.h5")


def test_damaged_parent_checkpoint_named_in_pair_record(run, tmp_path):
    """pair.json's library comparison with the parent checkpoint: sound -> [] here (same
    libraries); a damaged parent checkpoint -> one line saying it was not compared, never a
    comparison with corrupted provenance."""
    from gouge_cli.workflows.pairs import branch_bit_risks

    run_dir, slip = run
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    branch = work / f"forks/slip_{slip:03d}/drained"
    assert branch_bit_risks(branch) == []
    ck = work / f"checkpoints/slip_{slip:03d}.h5"
    _flip_text(ck, b"friction: 0.5", b"friction: 1.5")
    (line,) = branch_bit_risks(branch)
    assert line.startswith("not compared") and ck.name in line


def test_series_damage_after_the_checkpoints_row_is_left_to_the_resume(monkeypatch):
    """A damaged part of a series whose row before it is the checkpoint's own row (its clock, the
    part's time, equals the checkpoint's) holds only rows the resume drops and computes again:
    not refused; one starting a row earlier is."""
    from gouge_cli.io import verify
    from gouge_cli.io.verify import Problem, continued_problems

    def problems(time):
        return lambda path: ([Problem("/series/wall_x", "fails its checksum", "series", rows=(4096, 4200), time=time)],
                             True)

    monkeypatch.setattr(verify, "run_file_problems", problems(30000.0))
    assert continued_problems(Path("run.h5"), 30000.0, 3000, 0)[0] == []
    monkeypatch.setattr(verify, "run_file_problems", problems(29990.0))
    assert [p.object for p in continued_problems(Path("run.h5"), 30000.0, 3000, 0)[0]] == ["/series/wall_x"]
