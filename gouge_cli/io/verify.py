"""`gouge verify`: a scrub of a run directory, every byte of every file read and checked.

Checked: ``run.h5`` (the seal of every group and dataset, every chunk's Fletcher-32, the time
series increasing; :mod:`gouge_cli.io.integrity`), ``checkpoints/*.h5`` (their digest, see
:mod:`gouge_cli.io.checkpoint`) and the ``run.h5`` of every fork branch
(``forks/slip_NNN/<branch>``). Each file is sound, damaged (what is damaged: object, rows,
snapshot step, slip number) or unchecked (written before checksums: read in full, nothing to
compare with). For each damaged part the report names what recomputes it: the latest sound
checkpoint at or before it (or the config, from the start), and the command where one exists
(`gouge analyze` for /analysis, `gouge restart --force` for a fork branch, `gouge resume` for what
follows latest.h5). `resume` uses :func:`run_file_problems` on what it continues from.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

import h5py
import numpy as np

from ..errors import DamagedFileError, InputError
from .checkpoint import read_checkpoint
from .layout import RUN_FILE, ForkLayout, RunLayout, branch_flag
from .integrity import STRUCTURE_ERRORS, check_seal, damaged_rows, read, stored_seal, structure_error, walk_objects
from .integrity import attr_value
from .recovery import torn_series_tail
from .runreader import checked_time, run_status


@dataclass
class Problem:
    """One damaged part of a file. part: 'file' (root attributes, structure), 'series',
    'snapshot', 'slip' or 'analysis'; rows (series: first, last), step (snapshot), slip (number)."""

    object: str
    message: str
    part: str = "file"
    rows: tuple | None = None
    step: int | None = None
    slip: int | None = None
    time: float | None = None          # clock of the start of the damaged part, when known [t0]
    recompute: str | None = None
    unopened: bool | None = None       # True: the object itself cannot be opened (its metadata)


@dataclass
class FileReport:
    path: str
    kind: str                          # run, checkpoint, fork
    status: str                        # sound, damaged, unchecked
    problems: list = field(default_factory=list)
    time: float | None = None          # checkpoints: their clock [t0]
    recompute: str | None = None


def _part(path: str) -> dict:
    """Which part of a run file an HDF5 object path belongs to."""
    m = re.match(r"/snapshots/(\d+)", path)
    if m:
        return {"part": "snapshot", "step": int(m.group(1))}
    m = re.match(r"/slips/(\d+)", path)
    if m:
        return {"part": "slip", "slip": int(m.group(1))}
    if path.startswith("/series/") or path == "/series":
        return {"part": "series"}
    if path.startswith("/analysis"):
        return {"part": "analysis"}
    return {"part": "file"}


def run_file_problems(path: Path) -> tuple[list[Problem], bool]:
    """(problems, sealed) of a run file read in full: every object's seal (required when the
    root has one), every dataset's bytes, series time increasing and series lengths equal."""
    problems: list[Problem] = []
    try:
        h5 = h5py.File(path, "r")
    except OSError as err:
        return [Problem("/", f"cannot be opened as HDF5 ({str(err).splitlines()[0][:160]})")], False
    with h5:
        try:
            sealed = stored_seal(h5) is not None
        except DamagedFileError as err:
            return [Problem("/", str(err))], True
        objects, failures = walk_objects(h5)
        for name, err in failures.items():
            problems.append(Problem(name, f"cannot be opened ({str(err).splitlines()[0][:160]})", **_part(name),
                                    unopened=True))
        for name, obj in sorted(objects.items()):
            try:
                check_seal(obj, sealed)
            except DamagedFileError as err:
                problems.append(Problem(name, str(err), **_part(name)))
            if isinstance(obj, h5py.Dataset):
                try:
                    read(obj)
                except DamagedFileError as err:
                    rows = damaged_rows(obj) if obj.ndim == 1 and obj.chunks else []
                    extra = {"rows": (rows[0][0], rows[-1][1])} if rows and name.startswith("/series/") else {}
                    problems.append(Problem(name, str(err), **_part(name), **extra))
        try:
            t = checked_time(h5, False)
        except DamagedFileError as err:
            t = None
            if not any(p.object == "/series/time" for p in problems):
                row = re.search(r"row (\d+)", str(err))
                problems.append(Problem("/series/time", str(err), "series",
                                        rows=(int(row.group(1)), int(row.group(1))) if row else None))
        try:
            if "series" in h5:
                lengths = {n: ds.shape[0] for n, ds in h5["series"].items() if isinstance(ds, h5py.Dataset)}
                if len(set(lengths.values())) > 1:
                    problems.append(Problem("/series", f"series of different lengths ({lengths})", "lengths",
                                            rows=(min(lengths.values()), max(lengths.values()))))
        except STRUCTURE_ERRORS as err:
            problems.append(Problem("/series", str(structure_error(h5, err)), "series"))
        for p in problems:                  # the clock where each damaged part starts, when readable
            try:
                p.time = _start_time(h5, p, t)
            except STRUCTURE_ERRORS:
                p.time = None
    return problems, sealed


def continued_problems(path: Path, time: float, step: int, slips: int) -> tuple[list[Problem], list[Problem]]:
    """(kept, dropped): the problems of run file `path` in what a resume from a checkpoint at clock
    `time`, step `step`, after `slips` slips keeps (series rows up to `time`, snapshots up to
    `step`, slips up to `slips`, the root attributes), and in what it drops and computes again;
    /analysis is in neither (`gouge analyze` rewrites it)."""
    problems, _ = run_file_problems(path)
    kept, dropped = [], []
    for p in problems:
        if p.part != "analysis":
            (dropped if _follows(p, path, time, step, slips) else kept).append(p)
    return kept, dropped


def _follows(p: Problem, path: Path, time: float, step: int, slips: int) -> bool:
    """Whether damaged part `p` of run file `path` lies wholly after a checkpoint at (time, step,
    slips): what a resume from it drops and computes again."""
    if p.part == "snapshot":
        return p.step > step
    if p.part == "slip":
        return p.slip > slips
    if p.part == "series":
        # (its time is the clock of the row before its first: times increase strictly, so at or
        # after the checkpoint's clock every damaged row follows the checkpoint)
        return p.rows is not None and p.time is not None and p.time >= time
    if p.part == "lengths":
        return _rows_up_to(path, time) <= p.rows[0]
    return False


def _rows_up_to(path: Path, time: float) -> int:
    with h5py.File(path, "r") as h5:
        return int(np.searchsorted(read(h5["series"]["time"]), time, side="right"))


def _start_time(h5, p: Problem, t) -> float | None:
    try:
        if p.part == "series":
            return 0.0 if p.rows is None or t is None or p.rows[0] >= len(t) else float(t[max(p.rows[0] - 1, 0)])
        if p.part == "snapshot":
            return float(h5["snapshots"][f"{p.step:012d}"].attrs["time"])
        if p.part == "slip":
            return float(attr_value(h5["slips"][f"{p.slip:03d}"].attrs, "checkpoint_time"))
    except (OSError, KeyError, ValueError, TypeError, RuntimeError):
        return None
    return None


def _checkpoint_report(path: Path, root: Path) -> FileReport:
    rel = str(path.relative_to(root))
    try:
        ck = read_checkpoint(path)
    except InputError as err:
        return FileReport(rel, "checkpoint", "damaged", [Problem("/", str(err))])
    try:
        with h5py.File(path, "r") as h5:
            legacy = not str(attr_value(h5.attrs, "checksum", "")).startswith("sha256-v2:")
    except OSError:
        legacy = True
    return FileReport(rel, "checkpoint", "unchecked" if legacy else "sound", time=ck.time)


def _source(checkpoints: list[FileReport], time: float | None, before: str | None = None) -> str:
    """The latest sound checkpoint at or before `time` (None: unknown, from the start)."""
    good = [c for c in checkpoints if c.status != "damaged" and c.time is not None and c.path != before
            and time is not None and c.time <= time]
    if not good:
        return "config.yaml (from the start: `gouge run RUN/config.yaml --out NEW` gives the same bits)"
    best = max(good, key=lambda c: c.time)
    return f"{best.path} (t = {best.time:.6g} t0)"


def verify_run(run_dir: Path) -> dict:
    """Scrub a run directory (module doc). Returns {"run", "sound", "files": [FileReport as dict]}."""
    root = Path(run_dir)
    layout = RunLayout(root)
    if not layout.run_file.is_file():
        raise InputError(f"{root} is not a gouge run directory (no {RUN_FILE} in it)")
    checkpoints = [_checkpoint_report(p, root) for p in layout.checkpoint_files()]
    reports = []
    problems, sealed = run_file_problems(layout.run_file)
    main = FileReport(layout.relative(layout.run_file), "run", "damaged" if problems else ("sound" if sealed else "unchecked"), problems)
    latest = _resumed_from(layout)
    torn = _torn_tail(layout, latest)
    for p in problems:
        if p.part == "analysis":
            p.recompute = f"`gouge analyze {root}` (rewrites /analysis)"
        elif p.part == "series" and p.rows and (p.object.rsplit("/", 1)[-1], p.rows[0]) in torn:
            p.recompute = (f"`gouge resume {root}`, which mends it: a stop inside a write left this chunk's "
                           "checksum stale, and its rows up to checkpoints/latest.h5 match that checkpoint's record")
        elif latest is not None and _follows(p, layout.run_file, latest.time, latest.step, latest.header.slips):
            p.recompute = f"`gouge resume {root}`, which drops it and computes it again from checkpoints/latest.h5"
        else:
            p.recompute = _source(checkpoints, p.time)
    reports.append(main)
    for c in checkpoints:
        if c.status == "damaged":
            c.recompute = _source(checkpoints, _checkpoint_time_hint(root, c.path), before=c.path)
    reports.extend(checkpoints)
    for branch in layout.branch_run_files():
        rel = str(branch.relative_to(root))
        problems, sealed = run_file_problems(branch)
        report = FileReport(rel, "fork", "damaged" if problems else ("sound" if sealed else "unchecked"), problems)
        if problems:
            slip = ForkLayout(branch.parent.parent).slip
            perm = branch_flag(branch.parent.name)
            wanted = layout.relative(layout.slip_checkpoint(slip))
            source = next((c for c in checkpoints if c.path == wanted), None)
            state = "sound" if source and source.status != "damaged" else "damaged or missing"
            report.recompute = f"{wanted} ({state}): `gouge restart {root} --slip {slip}{perm} --force`"
        reports.append(report)
    return {"run": str(root), "sound": not any(r.status == "damaged" for r in reports),
            "files": [_plain(asdict(r)) for r in reports]}


def _resumed_from(layout: RunLayout):
    """The checkpoint `gouge resume` continues the run from (latest.h5), None when the run finished
    or it cannot be read."""
    try:
        if run_status(layout.run_file) in ("finished", None):
            return None
        return read_checkpoint(layout.latest)
    except (InputError, OSError, KeyError, ValueError, TypeError, RuntimeError):
        return None


def _torn_tail(layout: RunLayout, latest) -> set[tuple[str, int]]:
    """(column, first row) of the series chunks that `gouge resume` from checkpoint `latest` mends
    (recovery.torn_series_tail against its record)."""
    if latest is None:
        return set()
    try:
        tail = latest.header.series_tail
        return {(name, tail.start) for name in torn_series_tail(layout.run_file, tail)}
    except (OSError, KeyError, ValueError, TypeError, RuntimeError):
        return set()


def _checkpoint_time_hint(root: Path, rel: str) -> float | None:
    """A damaged slip checkpoint's clock from the run file's catalog (None if not known)."""
    m = re.search(r"slip_(\d+)\.h5$", rel)
    if not m:
        return None
    try:
        with h5py.File(RunLayout(root).run_file, "r") as h5:
            return float(attr_value(h5["slips"][f"{int(m.group(1)):03d}"].attrs, "checkpoint_time"))
    except (OSError, KeyError, ValueError, TypeError, RuntimeError):
        return None


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def describe_report(report: dict) -> str:
    """The report as lines for a terminal."""
    lines = []
    for f in report["files"]:
        lines.append(f"{f['status']:9s} {f['path']}" + (f" (t = {f['time']:.6g} t0)" if "time" in f else ""))
        for p in f.get("problems", []):
            where = (f" rows {p['rows'][0]}-{p['rows'][1]}" if "rows" in p else "")
            lines.append(f"          {p['object']}{where}: {p['message']}")
            if "recompute" in p:
                lines.append(f"            recompute from {p['recompute']}")
        if "recompute" in f:
            lines.append(f"          recompute from {f['recompute']}")
    damaged = sum(f["status"] == "damaged" for f in report["files"])
    unchecked = sum(f["status"] == "unchecked" for f in report["files"])
    lines.append(f"{report['run']}: {len(report['files'])} files, {damaged} damaged"
                 + (f", {unchecked} written without checksums (read in full, not compared)" if unchecked else ""))
    return "\n".join(lines)
