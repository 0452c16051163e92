"""What gouge's integrity checks cost: writing and reading a run with them and without.

    .venv/bin/python benchmarks/integrity_cost.py [CONFIG] [--repeats R] [--set KEY=VALUE ...] [--json PATH]
    e.g. benchmarks/integrity_cost.py configs/demo.yaml --repeats 3 --set run.duration=60000

The checks (docs/integrity.md): Fletcher-32 on every chunk of run.h5's series, snapshot and grid
datasets, an ``attrs_sha256`` seal on every group and dataset, and one SHA-256 digest over
everything a checkpoint holds. "Without" is the same code with those three switched off in this
process only (datasets written without the filter, no seals, an empty checkpoint digest), the
files as gouge wrote them before the checks existed.

Each repeat runs the scene once with checks and once without (taking turns, so that a slow
stretch of a shared machine hits both), timing, besides the run's wall time:

- write: the time spent inside the run-file writer (creating the file, appending and flushing
  series rows, snapshots, slips, closing) and in writing checkpoints;
- read: opening the finished run.h5 as the analysis does (root seal, time series), reading every
  series, every snapshot array and the slip catalog, and reading every checkpoint through
  read_checkpoint with its digest verified or not (best of 5 each), and `gouge analyze` without
  writing its tables (best of 3).

Printed as a table and written as JSON with the CPU, the numba target and the commit; the
numbers and the machine they were measured on go to docs/integrity.md.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import h5py
import yaml

from gouge_cli.config import build_config
from gouge_cli.driver import phases, slips
from gouge_cli.io import checkpoint, runwriter
from gouge_cli.io.checkpoint import read_checkpoint
from gouge_cli.io.runreader import RunReader
from gouge_cli.io.runwriter import RunFile
from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.workflows.run import run_scene

WRITER_METHODS = ("__init__", "append", "flush", "snapshot", "add_slip", "set_attr", "close")


class Clock:
    """Seconds spent in the wrapped calls, outermost calls only (append calls flush)."""

    def __init__(self):
        self.seconds = 0.0
        self.depth = 0

    def wrap(self, fn):
        def timed(*args, **kwargs):
            self.depth += 1
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.depth -= 1
                if self.depth == 0:
                    self.seconds += time.perf_counter() - t
        return timed


@contextlib.contextmanager
def patched(checks: bool, writer: Clock, ckpt: Clock):
    """Time the writer and the checkpoint writes; without checks, switch the three checks off."""
    saved = [(RunFile, m, getattr(RunFile, m)) for m in WRITER_METHODS]
    saved += [(mod, "write_checkpoint", mod.write_checkpoint) for mod in (phases, slips)]
    if not checks:
        saved += [(runwriter, "seal", runwriter.seal), (checkpoint, "content_digest", checkpoint.content_digest),
                  (h5py.Group, "create_dataset", h5py.Group.create_dataset)]
        create = h5py.Group.create_dataset

        def plain_dataset(self, name, *args, **kwargs):
            kwargs.pop("fletcher32", None)
            return create(self, name, *args, **kwargs)

        runwriter.seal = lambda obj: None
        checkpoint.content_digest = lambda h5, arrays=None, skip=("checksum",): ""
        h5py.Group.create_dataset = plain_dataset
    for m in WRITER_METHODS:
        setattr(RunFile, m, writer.wrap(getattr(RunFile, m)))
    for mod in (phases, slips):
        mod.write_checkpoint = ckpt.wrap(mod.write_checkpoint)
    try:
        yield
    finally:
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)


def read_run(run_dir: Path) -> float:
    """Seconds to open run.h5 and read every series, snapshot array and the slip catalog."""
    t = time.perf_counter()
    with RunReader(run_dir) as reader:
        names = list(reader.h5["series"])
        reader.series(names)
        for snap in reader.snapshot_names():
            for key in reader.h5["snapshots"][snap]:
                reader.snapshot_array(snap, key)
    slip_catalog(run_dir)
    return time.perf_counter() - t


def read_checkpoints(run_dir: Path, checks: bool) -> float:
    """Seconds to read every checkpoint of the run through read_checkpoint, its digest verified
    (checks) or not (the verification switched off)."""
    verify = checkpoint._verify
    if not checks:
        checkpoint._verify = lambda *args: None
    try:
        t = time.perf_counter()
        for path in sorted((run_dir / "checkpoints").glob("*.h5")):
            read_checkpoint(path)
        return time.perf_counter() - t
    finally:
        checkpoint._verify = verify


def analyze(run_dir: Path) -> float:
    """Seconds of `gouge analyze` without writing (catalog, fits, pairs from the run file); NaN
    for a run without slips (nothing to analyse)."""
    from gouge_cli.api import analyze as run_analysis
    from gouge_cli.errors import NoSlipsError

    t = time.perf_counter()
    try:
        run_analysis(run_dir, write=False)
    except NoSlipsError:
        return float("nan")
    return time.perf_counter() - t


def one_run(config, out: Path, checks: bool) -> dict:
    writer, ckpt = Clock(), Clock()
    with patched(checks, writer, ckpt):
        t = time.perf_counter()
        result = run_scene(config, out, force=True, quiet=True)
        wall = time.perf_counter() - t
    assert result.status == "finished", result.status
    files = sorted((out / "checkpoints").glob("*.h5"))
    return {"wall_s": wall, "write_run_h5_s": writer.seconds, "write_checkpoints_s": ckpt.seconds,
            "read_run_h5_s": min(read_run(out) for _ in range(5)),
            "read_checkpoints_s": min(read_checkpoints(out, checks) for _ in range(5)),
            "analyze_s": min(analyze(out) for _ in range(3)),
            "run_h5_bytes": (out / "run.h5").stat().st_size,
            "checkpoints": len(files), "checkpoint_bytes": sum(p.stat().st_size for p in files)}


def machine() -> dict:
    """Where it ran: gouge's provenance record (CPU model, vector width, numba target, library
    versions, commit), with HDF5's version and the date."""
    from gouge_cli.io import provenance

    return dict(provenance.collect(), hdf5=h5py.version.hdf5_version, date=time.strftime("%Y-%m-%d"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", nargs="?", default="configs/demo.yaml")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override")
    ap.add_argument("--json", default="runs/bench/integrity_cost.json")
    args = ap.parse_args(argv)
    config = build_config(yaml.safe_load(Path(args.config).read_text()), args.set)
    rows = {True: [], False: []}
    work = Path(tempfile.mkdtemp(prefix="gouge-integrity-cost-"))
    try:
        one_run(config, work / "warm", True)                     # numba compile, file-system caches
        for r in range(args.repeats):
            for checks in ((True, False) if r % 2 == 0 else (False, True)):
                rows[checks].append(one_run(config, work / f"{'with' if checks else 'without'}_{r}", checks))
                print(f"repeat {r + 1}/{args.repeats} {'with' if checks else 'without'} checks: "
                      + ", ".join(f"{k} {v:.4g}" for k, v in rows[checks][-1].items()), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med = {checks: {k: statistics.median(row[k] for row in rows[checks]) for k in rows[checks][0]}
           for checks in rows}
    report = {"machine": machine(), "config": args.config, "overrides": args.set, "repeats": args.repeats,
              "median_with": med[True], "median_without": med[False], "runs_with": rows[True],
              "runs_without": rows[False]}
    print(f"\n{'median of ' + str(args.repeats):<24}{'with':>12}{'without':>12}{'ratio':>8}")
    for key in ("wall_s", "write_run_h5_s", "write_checkpoints_s", "read_run_h5_s", "read_checkpoints_s",
                "analyze_s", "run_h5_bytes", "checkpoint_bytes"):
        a, b = med[True][key], med[False][key]
        print(f"{key:<24}{a:>12.4g}{b:>12.4g}{a / b if b else float('nan'):>8.3f}")
    extra = (med[True]["write_run_h5_s"] + med[True]["write_checkpoints_s"]
             - med[False]["write_run_h5_s"] - med[False]["write_checkpoints_s"])
    print(f"writing with checks costs {extra:.3g} s more, {100 * extra / med[False]['wall_s']:.2f} % of the run's "
          f"wall time ({med[False]['wall_s']:.3g} s)")
    print(json.dumps({k: report["machine"][k] for k in ("cpu", "git_commit", "hdf5", "date")}))
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
