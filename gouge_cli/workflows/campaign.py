"""`gouge campaign`: the pieces of a sweep, their ledger on disk, and their execution on Dask.

Layout of ``<out>/<name>/``::

    campaign.yaml               the spec as last run
    <point>/                    a gouge run directory (config.yaml, run.h5, checkpoints/, forks/)
      point.yaml                state point: overrides, resolved config, base, reproducing command
      ledger/run.json           one record per piece: state (running | done | failed | error),
      ledger/fork_NNN.json      settings it ran with, host, pid (and slurm_job), attempts, cause, result
      variants/<v>/forks/       the forks of a study variant other than the first (study.variants):
                                its run.h5, config.yaml and checkpoints/ are links to the point's
    results/<point>/*.json      one record per finished piece (workflows.campaign_results): what
                                outlives the machine; the tables are built from these alone
    table.csv  phase_diagram.csv  figures/
    regime.csv  delay.csv       the regime map (two permeabilities or more; regime/<value>/ per swept value)

A *piece* is one Dask task: "advance this run to completion" or "fork slip N of this run at the
study's permeabilities" (:func:`advance_run`, :func:`advance_fork`). A run piece whose worker
was lost resumes from ``checkpoints/latest.h5`` (at most one ``output.checkpoint_interval`` of
work is repeated); a fork piece starts again from its slip checkpoint (forks are short). What a
point does is an :class:`Action`; ``study`` = run, then fork every slip kept with a checkpoint.

A campaign finishes points before it starts new ones: at most as many points are in flight as
the cluster has task slots, and a point's forks go before any new loading. Each finished piece
writes its results record before its ledger says done. A piece whose record holds the settings
it would run with is done, whether or not its run folder is still there; a point whose forks are
not all recorded and whose run folder is gone runs its loading again (bitwise the same: the
record's final state hash is compared) and then only the missing forks.

Size (~500 lines): sweep expansion lives in campaign_spec.py and the executors in executors.py;
what is left (ledger, survey, Dask tasks, tables) is one workflow.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ..driver.progress import format_eta
from ..errors import CampaignConflict
from ..config import Config, build_config
from ..io.layout import CONFIG_FILE, OWNED, ForkLayout, RunLayout
from ..io.rundir import pid_alive
from .campaign_results import RUN_PIECE, PieceRecord, Results, diff_keys, fork_piece, settings_digest
from .campaign_spec import CampaignSpec, Point, expand, load_spec


# --------------------------------------------------------------------------- settings and ledger


def run_settings(config: Config) -> dict:
    """What a run's results depend on: its resolved config without numerics.threads (bitwise
    the same for any thread count) and name (a label)."""
    data = config.to_dict()
    data.pop("name", None)
    data["numerics"] = {k: v for k, v in data["numerics"].items() if k != "threads"}
    return data


digest = settings_digest      # the settings' hash (campaign_results owns it)


def _write_json(path: Path, data: dict):
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(data, indent=2, default=str))
    os.replace(tmp, path)


def read_ledger(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


# --------------------------------------------------------------------------- pieces and tasks


@dataclass(frozen=True)
class Piece:
    """One task: the run of a point, or the forks of one of its slips."""

    point: str
    kind: str                       # "run" | "fork"
    slip: int | None = None

    @property
    def label(self) -> str:
        return RUN_PIECE if self.kind == "run" else fork_piece(self.slip)


@dataclass(frozen=True)
class RecordTarget:
    """Where a piece's results record goes: the results folder, the campaign, the point and its
    swept values (picklable: it travels with the Dask task)."""

    results: str
    campaign: str
    point: str
    values: dict

    def write(self, piece: str, settings: dict, result: dict, wall_seconds: float) -> Path:
        return Results(self.results).write(PieceRecord(self.campaign, self.point, piece, settings, result,
                                                       wall_seconds=wall_seconds))


def _task(ledger: Path, settings: dict, body, record=None) -> dict:
    """Run ``body()`` with the piece's ledger kept: running -> done | failed (physics) | error.
    ``record(result, wall_seconds)``: writes the piece's results record, before the ledger says done."""
    from ..errors import PhysicsError

    previous = read_ledger(ledger) or {}
    entry = {"state": "running", "settings": settings, "host": socket.gethostname(), "pid": os.getpid(),
             "attempts": int(previous.get("attempts", 0)) + 1, "started": time.time()}
    if os.environ.get("SLURM_JOB_ID"):      # a worker started as a SLURM job (--slurm)
        entry["slurm_job"] = os.environ["SLURM_JOB_ID"]
    _write_json(ledger, entry)
    t0 = time.perf_counter()
    try:
        result = body()
    except PhysicsError as exc:
        entry.update(state="failed", cause=f"physics failure: {exc}".splitlines()[0], finished=time.time())
        _write_json(ledger, entry)
        return {"state": "failed", "cause": entry["cause"]}
    except BaseException as exc:
        entry.update(state="error", cause=f"{type(exc).__name__}: {exc}".splitlines()[0])
        _write_json(ledger, entry)
        raise
    wall = time.perf_counter() - t0
    if record is not None:
        record(result, wall)
    result["wall_seconds"] = wall
    entry.update(state="done", result=result, finished=time.time())
    _write_json(ledger, entry)
    return {"state": "done", **result}


def run_result(run_dir: Path) -> dict:
    """The results record's body of a finished loading run: its slips kept with checkpoints, its
    transient slips, its table row (analysis.campaign_table.run_row) and its final state hash."""
    from ..analysis.campaign_table import run_row
    from ..io.runreader import RunReader
    from ..io.slipcatalog import slip_catalog

    catalog = slip_catalog(run_dir)
    row, transient = run_row(run_dir)
    with RunReader(run_dir) as reader:
        final = str(reader.h5.attrs.get("final_state_hash", ""))
    return {"n_slips": len(catalog), "slips": [e.number for e in catalog if e.checkpoint],
            "transient": transient, "row": row, "final_state_hash": final}


def advance_run(run_dir: str, config: dict, settings: dict, target: RecordTarget | None = None,
                expect_hash: str | None = None) -> dict:
    """Dask task: bring the point's run to 'finished'. Resumes from checkpoints/latest.h5 when an
    earlier attempt left one; starts afresh otherwise. Returns the slips kept with checkpoints and
    writes the run's results record to ``target``. ``expect_hash``: the final state hash a record
    of this run holds (a loading run again after its folder was lost); RuntimeError if it differs."""
    from ..io.runreader import run_status
    from .run import resume_run, run_scene

    run_dir = Path(run_dir)
    layout = RunLayout(run_dir)

    def body():
        status = run_status(layout.run_file)
        resumed = status in ("running", "interrupted") and layout.latest.is_file()
        if status != "finished":
            result = resume_run(run_dir, quiet=True) if resumed else \
                run_scene(build_config(config), run_dir, force=True, quiet=True)
            if result.status != "finished":
                raise RuntimeError(f"{run_dir}: the run stopped with status {result.status!r}")
        out = run_result(run_dir)
        if expect_hash and out["final_state_hash"] != expect_hash:
            raise RuntimeError(f"{run_dir}: the loading ran again ends in state {out['final_state_hash']}, its "
                               f"results record in {expect_hash}: not the same run bit for bit")
        return {"resumed": resumed, **out}

    def record(result, wall):
        if target is not None:
            target.write(RUN_PIECE, settings, {"values": target.values, **result}, wall)

    return _task(run_dir / "ledger" / "run.json", settings, body, record)


VARIANTS = "variants"


def variant_dir(run_dir: Path, name: str) -> Path:
    """``<point>/variants/<name>``: a run directory whose run.h5, config.yaml and checkpoints/ are
    links to the point's, so that a variant's forks (other fluid settings) start from the same
    packing and sit in a fork layout of their own."""
    vdir = Path(run_dir) / VARIANTS / name
    (vdir / "ledger").mkdir(parents=True, exist_ok=True)
    layout, target = RunLayout(vdir), RunLayout(run_dir)
    for link, to in ((layout.run_file, target.run_file), (layout.config_file, target.config_file),
                     (layout.checkpoints, target.checkpoints)):
        if not link.is_symlink():
            link.symlink_to(os.path.relpath(to, link.parent))
    return vdir


def _share_drained(base_fork: Path, fork: Path):
    """The variant's fork gets the base fork's drained branch (a link: the drained twin has no
    fluid, so it is the same for every variant) and loses its undrained branches (run afresh)."""
    from ..io.layout import DRAINED

    fork.mkdir(parents=True, exist_ok=True)
    drained = fork / DRAINED
    if drained.is_symlink() or drained.is_file():
        drained.unlink()
    elif drained.is_dir():
        shutil.rmtree(drained)
    drained.symlink_to(os.path.relpath(base_fork / DRAINED, fork))
    for branch in ForkLayout(fork).undrained_dirs():
        shutil.rmtree(branch)


def advance_fork(run_dir: str, slip: int, permeabilities: list[float], duration: float | None,
                 settings: dict, target: RecordTarget | None = None,
                 variants: list[tuple[str, dict]] | None = None) -> dict:
    """Dask task: drained + undrained branches of one slip (:func:`gouge_cli.workflows.fork.run_fork`),
    started afresh from the slip checkpoint (any partial branches of a lost attempt are replaced),
    then the fork's pair.json (the one pair definition, :mod:`gouge_cli.workflows.pairs`), once per
    variant (name, fork overrides): the first in the point's forks/, the others in
    variants/<name>/forks/ with the first's drained branch. Writes the fork's results record
    (one pair row per variant and permeability) to ``target``."""
    from .fork import ForkRequest, run_fork
    from .pairs import write_pair_json

    run_dir = Path(run_dir)
    chosen = variants or [(None, {})]

    def body():
        statuses = {}
        base_fork = RunLayout(run_dir).fork(slip).root
        for i, (name, overrides) in enumerate(chosen):
            vdir = run_dir if i == 0 else variant_dir(run_dir, name)
            fork = RunLayout(vdir).fork(slip).root
            if i:
                _share_drained(base_fork, fork)
            summary = run_fork(ForkRequest(vdir, slip, tuple(permeabilities), overrides, duration=duration,
                                           force=(i == 0)), quiet=True)
            write_pair_json(fork)
            prefix = f"{name}/" if name else ""
            statuses.update({prefix + k: b.status for k, b in summary.branches.items()})
        return {"branches": statuses, **fork_result(run_dir, slip, permeabilities, variants)}

    def record(result, wall):
        if target is not None:
            target.write(fork_piece(slip), settings, {"slip": slip, **result}, wall)

    return _task(run_dir / "ledger" / f"{fork_piece(slip)}.json", settings, body, record)


def fork_result(run_dir: Path, slip: int, permeabilities: list[float],
                variants: list[tuple[str, dict]] | None) -> dict:
    """The results record's pairs and branch hashes of slip ``slip``'s forks (every variant), read
    from the run folder: ``{"pairs": [pair rows, with 'variant' where the study has variants],
    "final_state_hashes": {variant/branch: hash}}`` (a variant's linked drained branch once)."""
    from ..analysis.campaign_table import fork_rows
    from ..io.runreader import RunReader

    pairs, hashes = [], {}
    for i, (name, _) in enumerate(variants or [(None, {})]):
        fork = RunLayout(run_dir if i == 0 else Path(run_dir) / VARIANTS / name).fork(slip).root
        prefix = f"{name}/" if name else ""
        for row in fork_rows(fork, permeabilities):
            pairs.append({"variant": name, **row} if name else row)
        for branch in sorted(fork.iterdir()):
            if RunLayout(branch).run_file.is_file() and not (i and branch.is_symlink()):
                with RunReader(branch) as reader:
                    hashes[prefix + branch.name] = str(reader.h5.attrs.get("final_state_hash", ""))
    return {"pairs": pairs, "final_state_hashes": hashes}


class Action:
    """What a point does: its first pieces, and the pieces a finished piece opens."""

    name = "run"

    def __init__(self, spec: CampaignSpec):
        self.spec = spec

    def after(self, point: str, piece: Piece, result: dict) -> list[Piece]:
        return []

    def settings(self, piece: Piece, run: dict) -> dict:
        return run


class StudyAction(Action):
    """Run, then fork every slip kept with a checkpoint (every non-transient one with
    ``study.skip_transient``) at the study's permeabilities, once per variant. (The per-slip step
    is :func:`advance_fork`; a `gouge study` workflow can replace it here.)"""

    name = "study"

    def after(self, point, piece, result):
        if piece.kind != "run" or result.get("state") != "done":
            return []
        skip = set(result.get("transient", ())) if self.spec.study.skip_transient else set()
        return [Piece(point, "fork", n) for n in result["slips"] if n not in skip]

    def settings(self, piece, run):
        if piece.kind == "run":
            return run
        study = self.spec.study
        out = {"run": digest(run), "slip": piece.slip, "permeabilities": list(study.permeabilities),
               "duration": study.duration}
        if study.variants:
            out["variants"] = study.variants
        return out


def make_action(spec: CampaignSpec) -> Action:
    return {"run": Action, "study": StudyAction}[spec.action](spec)


# --------------------------------------------------------------------------- survey


@dataclass
class PieceState:
    """Where one piece stands. ``record``: its ledger entry (or, for a piece known from its
    results alone, one made from the results record); ``result``: its results record, if any."""

    piece: Piece
    state: str            # done | running | interrupted | failed | left | conflict
    detail: str = ""
    record: dict | None = None
    result: PieceRecord | None = None


@dataclass
class Survey:
    """Where every piece of a campaign stands, read from the point directories."""

    spec: CampaignSpec
    root: Path
    points: list[Point]
    results: Results
    pieces: list[PieceState] = field(default_factory=list)
    unknown_forks: list[str] = field(default_factory=list)   # runs not done yet: forks to come

    def by_state(self, *states) -> list[PieceState]:
        return [p for p in self.pieces if p.state in states]

    def point(self, name: str) -> Point:
        return next(p for p in self.points if p.name == name)

    def point_dir(self, name: str) -> Path:
        return self.root / name


def _worker_gone(record: dict) -> bool:
    """Whether the worker of a 'running' ledger record is known to be gone: its process on this
    host, or else its SLURM job (ended: walltime, scancel), no longer exists."""
    if record.get("host") == socket.gethostname():
        return not pid_alive(int(record.get("pid", 0)))
    if record.get("slurm_job"):
        return slurm_job_alive(str(record["slurm_job"])) is False
    return False


def slurm_job_alive(job: str) -> bool | None:
    """Whether SLURM job ``job`` is pending or running (``squeue``); None when squeue cannot tell."""
    try:
        out = subprocess.run(["squeue", "-h", "-j", job, "-o", "%T"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if out.returncode != 0:
        return False if "Invalid job id" in out.stderr else None
    return bool(out.stdout.strip())


def _piece_state(piece: Piece, ledger: Path, settings: dict, output: Path,
                 result: PieceRecord | None = None) -> PieceState:
    record = read_ledger(ledger)
    if result is not None and result.digest == settings_digest(settings):
        entry = record if record and record.get("state") == "done" else \
            {"state": "done", "settings": result.settings, "result": result.result, "finished": result.finished}
        return PieceState(piece, "done", "" if entry is record else "from its results record", entry, result)
    if record is None and result is not None:
        record = {"state": "done", "settings": result.settings, "finished": result.finished}
    if record is None:
        if output.exists():
            return PieceState(piece, "conflict", f"{output} exists but was not made by this campaign")
        return PieceState(piece, "left")
    old = record.get("settings") or {}
    changed = diff_keys(old, settings)
    perms_only = piece.kind == "fork" and changed and not diff_keys(
        {k: v for k, v in old.items() if k != "permeabilities"},
        {k: v for k, v in settings.items() if k != "permeabilities"})
    state = record.get("state")
    if state == "running":
        if _worker_gone(record):
            state, detail = "interrupted", f"worker lost after attempt {record.get('attempts')}; resumes"
        else:
            detail = f"on {record.get('host')} pid {record.get('pid')}, attempt {record.get('attempts')}"
    elif state == "error":
        state, detail = "interrupted", f"attempt {record.get('attempts')} stopped: {record.get('cause', '')}"
    elif state == "failed":
        detail = record.get("cause", "")
    else:
        detail = ""
    if perms_only and state != "running":
        return PieceState(piece, "left", "permeabilities changed: forked again", record)
    if changed and state in ("done", "failed", "interrupted"):
        return PieceState(piece, "conflict", "; ".join(changed), record, result)
    return PieceState(piece, state, detail, record, result)


def results_root(spec: CampaignSpec) -> Path:
    """The campaign's results folder: the spec's ``results``, else ``<out>/<name>/results``."""
    return Path(spec.results).resolve() if spec.results else Path(spec.out).resolve() / spec.name / "results"


def survey(spec: CampaignSpec, spec_path: Path) -> Survey:
    points = expand(spec, Path(spec_path))
    root = Path(spec.out).resolve() / spec.name
    results = Results(results_root(spec))
    records = results.records()
    out = Survey(spec, root, points, results)
    action = make_action(spec)
    for point in points:
        pdir = root / point.name
        run = run_settings(point.config)
        rs = _piece_state(Piece(point.name, "run"), pdir / "ledger" / "run.json", run, RunLayout(pdir).run_file,
                          records.get((point.name, RUN_PIECE)))
        out.pieces.append(rs)
        if rs.state == "done":
            forks = []
            for piece in action.after(point.name, rs.piece, rs.record.get("result", {}) | {"state": "done"}):
                ledger = pdir / "ledger" / f"{piece.label}.json"
                pair_file = RunLayout(pdir).fork(piece.slip).pair_file
                forks.append(_piece_state(piece, ledger, action.settings(piece, run), pair_file,
                                          records.get((point.name, piece.label))))
            out.pieces += forks
            missing = [f for f in forks if f.state in ("left", "interrupted")]
            if missing and not RunLayout(pdir).run_file.is_file():
                rs.state = "left"
                rs.detail = (f"its run folder is gone and {len(missing)} forks are not recorded: the loading runs "
                             "again (bitwise, checked against its record)")
        elif spec.action == "study":
            out.unknown_forks.append(point.name)
    return out


def status_lines(s: Survey) -> list[str]:
    """`gouge campaign --status`: counts, then one line per piece that is not done."""
    counts = {k: len(s.by_state(k)) for k in ("done", "running", "interrupted", "failed", "conflict", "left")}
    head = (f"campaign {s.spec.name} ({s.root}): {len(s.points)} points, {len(s.pieces)} pieces known: "
            f"{counts['done']} done, {counts['running']} running, {counts['failed']} failed, "
            f"{counts['left'] + counts['interrupted']} left ({counts['interrupted']} to resume)")
    if counts["conflict"]:
        head += f", {counts['conflict']} with changed settings (need --force)"
    lines = [head]
    if s.unknown_forks:
        lines.append(f"  + the forks of {len(s.unknown_forks)} runs not finished yet")
    for p in s.pieces:
        if p.state != "done":
            lines.append(f"  {p.state:11s} {p.piece.point} {p.piece.label}" + (f": {p.detail}" if p.detail else ""))
    return lines


# --------------------------------------------------------------------------- execution


def _write_point(s: Survey, point: Point):
    pdir = s.point_dir(point.name)
    pdir.mkdir(parents=True, exist_ok=True)
    state = {"campaign": s.spec.name, "point": point.name, "overrides": point.overrides, "set": point.fixed,
             "base": str(point.base), "action": s.spec.action,
             "study": s.spec.study.model_dump() if s.spec.study else None,
             "command": point.command(pdir), "config": point.config.to_dict()}
    path = pdir / "point.yaml"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(yaml.safe_dump(state, sort_keys=False))
    os.replace(tmp, path)


def _wipe(s: Survey, ps: PieceState):
    """Remove a conflicting piece's results (``--force``): a run takes its forks with it, and its
    results records."""
    pdir = s.point_dir(ps.piece.point)
    if ps.piece.kind == "run":
        for name in [n for n in OWNED if n != CONFIG_FILE] + ["ledger", VARIANTS]:
            target = pdir / name
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
        for record in s.results.root.glob(f"{ps.piece.point}/*.json"):
            record.unlink()
    else:
        (pdir / "ledger" / f"{ps.piece.label}.json").unlink(missing_ok=True)
        s.results.path(ps.piece.point, ps.piece.label).unlink(missing_ok=True)


@dataclass
class CampaignReport:
    survey: Survey
    submitted: int
    finished: dict          # state -> count of this invocation's pieces
    wall_seconds: float
    outputs: dict


def run_campaign(spec_path: Path, *, client=None, cluster=None, force: bool = False,
                 retry_failed: bool = False, max_points: int | None = None, tables_only: bool = False,
                 reanalysed: bool = False, log=print) -> CampaignReport:
    """Run what is left of a campaign on Dask and write its table and figures.

    ``client``: a ``distributed.Client`` to use; otherwise one is opened for ``cluster``
    (:class:`~gouge_cli.workflows.executors.ClusterOptions`, default a LocalCluster) only when
    something is left to run. Raises :class:`CampaignConflict` when results exist with other
    settings and ``force`` is not given. ``max_points``: overrides the spec's limit on the sweep's size.
    ``tables_only``: run nothing; write the tables and figures from the results records
    (``reanalysed``: after :func:`reanalyse`).
    """
    from .executors import ClusterOptions, open_client

    t_start = time.perf_counter()
    spec_path = Path(spec_path)
    spec = load_spec(spec_path, max_points)
    s = survey(spec, spec_path)
    if tables_only:
        backfill(s, log)
        if reanalysed:
            reanalyse(s, log)
            s = survey(spec, spec_path)
        return CampaignReport(s, 0, {}, time.perf_counter() - t_start, write_results(s, log))
    conflicts = s.by_state("conflict")
    if conflicts and not force:
        lines = [f"  {c.piece.point} {c.piece.label}: {c.detail}" for c in conflicts]
        raise CampaignConflict(f"campaign {spec.name}: {len(conflicts)} pieces hold results made with other "
                               "settings:\n" + "\n".join(lines) +
                               "\n  pass --force to run them again (their old results are deleted), or "
                               "give the campaign another name")
    for c in conflicts:
        _wipe(s, c)
    s.root.mkdir(parents=True, exist_ok=True)
    if not (s.root / "campaign.yaml").is_file() or (s.root / "campaign.yaml").read_bytes() != spec_path.read_bytes():
        shutil.copyfile(spec_path, s.root / "campaign.yaml")
    for point in s.points:
        if not (s.point_dir(point.name) / "point.yaml").is_file() or any(
                c.piece.point == point.name and c.piece.kind == "run" for c in conflicts):
            _write_point(s, point)
    backfill(s, log)
    todo_states = {"left", "interrupted", "conflict"} | ({"failed"} if retry_failed else set())
    todo = [p for p in s.pieces if p.state in todo_states]
    busy = s.by_state("running")
    for b in busy:
        log(f"skipping {b.piece.point} {b.piece.label}: already running ({b.detail})")
    finished: dict[str, int] = {}
    if todo:
        opts = cluster or ClusterOptions()
        if client is not None:
            finished = _execute(s, todo, client, opts, log)
        else:
            with open_client(opts) as c:
                finished = _execute(s, todo, c, opts, log)
    s = survey(spec, spec_path)
    outputs = write_results(s, log) if (finished or _results_stale(s)) else {}
    return CampaignReport(s, sum(finished.values()), finished, time.perf_counter() - t_start, outputs)


def backfill(s: Survey, log=print):
    """Write the missing results records of pieces whose ledger says done (a campaign run
    before records existed), from their run folders."""
    for ps in s.by_state("done"):
        if ps.result is not None or ps.piece.kind != "run" and not ps.record.get("result"):
            continue
        point = s.point(ps.piece.point)
        pdir = s.point_dir(point.name)
        target = _target(s, point)
        if not RunLayout(pdir).run_file.is_file():
            continue
        if ps.piece.kind == "run":
            result = {"values": target.values, "resumed": ps.record.get("result", {}).get("resumed", False),
                      **run_result(pdir)}
        else:
            if not RunLayout(pdir).fork(ps.piece.slip).root.is_dir():
                continue
            result = {"slip": ps.piece.slip, "branches": ps.record["result"].get("branches", {}),
                      **fork_result(pdir, ps.piece.slip, list(s.spec.study.permeabilities), _variants(s.spec))}
        record = PieceRecord(s.spec.name, point.name, ps.piece.label, ps.record["settings"], result,
                             wall_seconds=float(ps.record.get("result", {}).get("wall_seconds", 0.0)),
                             finished=float(ps.record.get("finished", time.time())))
        ps.result = record
        s.results.write(record)
        log(f"results record written for {point.name} {ps.piece.label} (from its run folder)")


def reanalyse(s: Survey, log=print) -> int:
    """Rewrite the results of every recorded piece whose run folder is on this machine with this
    gouge's analysis (a run's row and transient slips, a fork's pair rows), keeping the settings,
    machine and wall time of the run and adding ``reanalysed`` (commit, time): how a new pair
    column reaches the records while the folders exist. Returns the number rewritten."""
    from dataclasses import replace

    from ..io import provenance

    n = 0
    for ps in s.by_state("done"):
        pdir = s.point_dir(ps.piece.point)
        if ps.result is None or not RunLayout(pdir).run_file.is_file():
            continue
        if ps.piece.kind == "run":
            result = {**ps.result.result, **run_result(pdir)}
        elif RunLayout(pdir).fork(ps.piece.slip).root.is_dir():
            result = {**ps.result.result, **fork_result(pdir, ps.piece.slip, list(s.spec.study.permeabilities),
                                                        _variants(s.spec))}
        else:
            continue
        result["reanalysed"] = {"git_commit": provenance.git_commit(), "time": time.time()}
        s.results.write(replace(ps.result, result=result))
        n += 1
    log(f"{n} results records analysed again from their run folders")
    return n


def _target(s: Survey, point: Point) -> RecordTarget:
    return RecordTarget(str(s.results.root), s.spec.name, point.name,
                        {k: _value(point.config, k) for k in s.spec.swept_keys()})


def _variants(spec: CampaignSpec) -> list[tuple[str, dict]] | None:
    study = spec.study
    return list(study.variants.items()) if study and study.variants else None


def _submit(client, s: Survey, ps: PieceState, retries: int, token: str):
    piece = ps.piece
    point = s.point(piece.point)
    pdir = str(s.point_dir(piece.point))
    action = make_action(s.spec)
    run = run_settings(point.config)
    key = f"gouge-{s.spec.name}-{piece.point}-{piece.label}-{token}"
    target = _target(s, point)
    if piece.kind == "run":
        expect = ps.result.result.get("final_state_hash") if ps.result is not None else None
        return client.submit(advance_run, pdir, point.config.to_dict(), run, target, expect, key=key,
                             retries=retries, pure=False)
    study = s.spec.study
    return client.submit(advance_fork, pdir, piece.slip, list(study.permeabilities), study.duration,
                         action.settings(piece, run), target, _variants(s.spec), key=key, retries=retries,
                         pure=False, priority=1)       # a point's forks go before a new loading


def task_slots(client, opts) -> int:
    """Tasks the cluster runs at once (its workers' threads); at least 1 (and, before SLURM
    workers have joined, the local --workers given)."""
    try:
        n = sum(int(w.get("nthreads", 1)) for w in client.scheduler_info()["workers"].values())
    except Exception:       # noqa: BLE001  a scheduler that cannot say: one at a time
        n = 0
    return max(1, n or (opts.workers or 0))


def campaign_eta(seconds: dict[str, list[float]], forks_left: int, runs_left: int, forks_per_run: float,
                 slots: int) -> float:
    """Wall seconds left [s]: the forks queued, and per loading still to run (waiting or running)
    the loading and its forks, each at the median wall time of its kind so far (``seconds``:
    {"run": [...], "fork": [...]}, this campaign's records and this session's pieces), over the
    task slots. NaN until a piece of each kind needed has finished."""
    import statistics

    fork = statistics.median(seconds["fork"]) if seconds["fork"] else math.nan
    run = statistics.median(seconds["run"]) if seconds["run"] else (0.0 if not runs_left else math.nan)
    work = forks_left * fork + runs_left * (run + forks_per_run * fork) if forks_left or runs_left else 0.0
    return work / max(slots, 1)


def _execute(s: Survey, todo: list[PieceState], client, opts, log) -> dict[str, int]:
    """Finish points before starting new ones: the forks of points whose run is done go first;
    a new loading starts only while fewer points are in flight than the cluster has task slots.
    Each finished piece opens the pieces that follow it (not those already recorded)."""
    from distributed import as_completed

    action = make_action(s.spec)
    token = os.urandom(3).hex()
    known = {(p.piece.point, p.piece.label): p for p in s.pieces}
    runs = [p for p in todo if p.piece.kind == "run"]
    loading = {p.piece.point for p in runs}
    futures, in_flight = {}, {}
    queue = as_completed([])

    def submit(ps: PieceState):
        fut = _submit(client, s, ps, opts.retries, token)
        futures[fut] = ps.piece
        in_flight[ps.piece.point] = in_flight.get(ps.piece.point, 0) + 1
        queue.add(fut)

    def fill():
        while runs and len(in_flight) < task_slots(client, opts):
            submit(runs.pop(0))

    seconds: dict[str, list[float]] = {"run": [], "fork": []}       # (for the ETA: campaign_eta)
    for p in s.pieces:
        if p.state == "done" and p.result is not None and p.result.wall_seconds:
            seconds[p.piece.kind].append(float(p.result.wall_seconds))
    forked = [p.piece.point for p in s.pieces if p.piece.kind == "fork" and p.state == "done"]
    forks_per_run = len(forked) / len(set(forked)) if forked else 0.0

    def eta() -> str:
        pending = list(futures.values())
        left = campaign_eta(seconds, sum(p.kind == "fork" for p in pending),
                            sum(p.kind == "run" for p in pending) + len(runs), forks_per_run,
                            task_slots(client, opts))
        return f"; ETA ~{format_eta(left)}" if math.isfinite(left) else ""

    for ps in todo:
        if ps.piece.kind == "fork" and ps.piece.point not in loading:
            submit(ps)
    fill()
    done: dict[str, int] = {}
    n = 0
    for fut in queue:
        piece = futures.pop(fut)
        n += 1
        try:
            result = fut.result()
        except Exception as exc:        # retries used up, or the worker was lost too often
            cause = f"{type(exc).__name__}: {exc}".splitlines()[0]
            ledger = s.point_dir(piece.point) / "ledger" / f"{piece.label}.json"
            record = read_ledger(ledger) or {}
            record.update(state="failed", cause=cause, finished=time.time())
            _write_json(ledger, record)
            result = {"state": "failed", "cause": cause}
        state = result["state"]
        done[state] = done.get(state, 0) + 1
        if state == "done" and result.get("wall_seconds"):
            seconds[piece.kind].append(float(result["wall_seconds"]))
        for nxt in action.after(piece.point, piece, result):
            ps = known.get((nxt.point, nxt.label))
            if ps is None or ps.state not in ("done", "running"):
                submit(ps if ps is not None and ps.state != "conflict" else PieceState(nxt, "left"))
        in_flight[piece.point] -= 1
        if not in_flight[piece.point]:
            del in_flight[piece.point]
        extra = f" ({result['wall_seconds']:.1f} s" + (", resumed" if result.get("resumed") else "") + \
            (f", {len(result['slips'])} slips to fork" if "slips" in result and s.spec.action == "study" else "") + ")" \
            if state == "done" else f": {result.get('cause', '')}"
        log(f"[{n} finished, {len(futures)} queued, {len(runs)} points waiting] {piece.point} {piece.label}: "
            f"{state}{extra}" + ("" if piece.point in in_flight or state != "done" else "; point finished") + eta())
        fill()
    return done


# --------------------------------------------------------------------------- results


def _results_stale(s: Survey) -> bool:
    table = s.root / "table.csv"
    if not table.is_file():
        return bool(s.by_state("done"))
    newest = max((p.record or {}).get("finished", 0) for p in s.pieces) if s.pieces else 0
    return newest > table.stat().st_mtime


def table_rows(s: Survey) -> list[dict]:
    """The campaign table's rows, from the results records alone: per point whose run is
    recorded, its run row (``kind`` 'run': swept values, the run statistics and their
    :func:`~gouge_cli.analysis.campaign_table.reload_columns`), then one row per
    recorded pair (``kind`` 'pair': swept values, variant if the study has variants, the pair
    columns, and ``transient``), in sweep then slip order."""
    from ..analysis.campaign_table import reload_columns

    swept = s.spec.swept_keys()
    records = {(p.piece.point, p.piece.label): p.result for p in s.pieces
               if p.state == "done" and p.result is not None}
    rows = []
    for point in s.points:
        run = records.get((point.name, RUN_PIECE))
        if run is None:
            continue
        values = {k: run.result["values"].get(k) for k in swept}
        loading = point.config.loading
        rows.append({"kind": "run", "point": point.name, **values, **run.result["row"],
                     **reload_columns(run.result["row"], loading.normal_stress, loading.spring_constant,
                                      loading.velocity)})
        transient = set(run.result.get("transient", ()))
        forks = sorted((r for (name, label), r in records.items() if name == point.name and label != RUN_PIECE),
                       key=lambda r: r.result["slip"])
        for fork in forks:
            for pair in fork.result["pairs"]:
                rows.append({"kind": "pair", "point": point.name, **values, **pair,
                             "transient": int(pair["slip"]) in transient})
    return rows


def spec_pairs(spec_path: Path) -> tuple[list[dict], list[str]]:
    """(pair rows, the keys they are never pooled over: the swept keys but the seed, and the study
    variant) of a campaign, from its results records."""
    spec = load_spec(spec_path)
    rows = [r for r in table_rows(survey(spec, spec_path)) if r["kind"] == "pair"]
    for r in rows:
        r.setdefault("seed", "")
    keys = [k for k in spec.swept_keys() if k != "seed"]
    if spec.study and spec.study.variants:
        keys.append("variant")
    return rows, keys


def done_points(s: Survey) -> list[str]:
    """The points whose run is recorded (the rows of table.csv and gouge_cli.api.open_campaign)."""
    return [p.piece.point for p in s.pieces if p.piece.kind == "run" and p.state == "done" and p.result is not None]


def write_results(s: Survey, log=print) -> dict:
    """table.csv (one row per run and per pair), phase_diagram.csv and the figures, from the
    results records alone."""
    from ..analysis.campaign_table import PHASE_COLUMNS, pairs_by_permeability, phase_cells, write_table
    from ..plots.phase import pair_histograms, phase_diagram_figure, sweep_figure
    from .campaign_spec import phase_axes

    swept = [k for k in s.spec.swept_keys()]
    rows = table_rows(s)
    out = {"table": write_table(rows, swept, s.root / "table.csv")}
    figs = s.root / "figures"
    pair_rows = [r for r in rows if r["kind"] == "pair"]
    if s.spec.action == "study":
        x, y = phase_axes(s.spec)
        for variant, vrows in _by_variant(pair_rows, s.spec):
            cells = phase_cells(vrows, x, y)
            where = f"_{variant}" if variant else ""
            out[f"phase_csv{where}"] = write_table(cells, [], s.root / f"phase_diagram{where}.csv",
                                                   columns=list(PHASE_COLUMNS))
            if cells:
                out[f"phase_diagram{where}"] = phase_diagram_figure(
                    cells, x, y, figs / f"phase_diagram{where}.png",
                    s.spec.name + (f", variant {variant}" if variant else ""))
            out[f"pair_histograms{where}"] = pair_histograms(pairs_by_permeability(vrows),
                                                             figs / variant if variant else figs)
            for c in cells:
                log(f"phase cell{' ' + variant if variant else ''} {x}={c['x']:g}" + (f", {y}={c['y']:g}" if y else "") +
                    f": {c['n_pairs']} pairs, complex fraction {c['frac_complex']:.3g}, Type II fraction "
                    f"{c['frac_type_II']:.3g}")
    if s.spec.action == "study" and len(s.spec.study.permeabilities) >= 2:
        out.update(_regime_outputs(pair_rows, s, figs))
    sweep_keys = [k for k in swept if k != "seed"]
    if sweep_keys:
        out["slip_statistics"] = sweep_figure([r for r in rows if r["kind"] == "run"], sweep_keys,
                                              figs / "slip_statistics.png", s.spec.name)
    return out


def _by_variant(pair_rows: list[dict], spec: CampaignSpec) -> list[tuple[str, list[dict]]]:
    """The pair rows per study variant (never pooled); one group named '' without variants."""
    names = list(spec.study.variants) if spec.study and spec.study.variants else [None]
    return [(name or "", [r for r in pair_rows if r.get("variant") == name]) for name in names]


def _regime_outputs(pair_rows: list[dict], s: Survey, figs: Path) -> dict:
    """regime.csv, delay.csv, mechanism.csv and their figures (workflows.regime_report), for a study
    campaign with two permeabilities or more; a campaign that sweeps more than seeds, or has study
    variants, gets one set per value of those keys under regime/<key>-<value>_.../, with its
    pairs.csv (permeabilities, variants and other swept values are never pooled)."""
    from .regime_report import write_groups, write_regime

    keys = [k for k in s.spec.swept_keys() if k != "seed"] + (["variant"] if _variants(s.spec) else [])
    if not keys:
        return write_regime(pair_rows, s.root, figs, s.spec.name)
    return write_groups(pair_rows, keys, s.root / "regime", s.spec.name)


def _value(config: Config, key: str) -> float:
    """The resolved (dimensionless) value of a dotted config key."""
    node = config.to_dict()
    for part in key.split("."):
        node = node[part]
    return node


__all__ = ["Piece", "Survey", "advance_run", "advance_fork", "survey", "status_lines", "results_root", "backfill",
           "spec_pairs",
           "run_campaign", "write_results", "table_rows", "done_points", "run_settings", "load_spec"]
