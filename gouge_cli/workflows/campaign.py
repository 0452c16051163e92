"""`gouge campaign`: the pieces of a sweep, their ledger on disk, and their execution on Dask.

Layout of ``<out>/<name>/``::

    campaign.yaml               the spec as last run
    <point>/                    a gouge run directory (config.yaml, run.h5, checkpoints/, forks/)
      point.yaml                state point: overrides, resolved config, base, reproducing command
      ledger/run.json           one record per piece: state (running | done | failed | error),
      ledger/fork_NNN.json      settings it ran with, host, pid (and slurm_job), attempts, cause, result
    table.csv  phase_diagram.csv  figures/
    regime.csv  delay.csv       the regime map (two permeabilities or more; regime/<value>/ per swept value)

A *piece* is one Dask task: "advance this run to completion" or "fork slip N of this run at the
study's permeabilities" (:func:`advance_run`, :func:`advance_fork`). A run piece whose worker
was lost resumes from ``checkpoints/latest.h5`` (at most one ``output.checkpoint_interval`` of
work is repeated); a fork piece starts again from its slip checkpoint (forks are short). What a
point does is an :class:`Action`; ``study`` = run, then fork every slip kept with a checkpoint.

Size (~500 lines): sweep expansion lives in campaign_spec.py and the executors in executors.py;
what is left (ledger, survey, Dask tasks, tables) is one workflow.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ..errors import CampaignConflict
from ..config import Config, build_config
from ..io.layout import CONFIG_FILE, OWNED, RunLayout
from ..io.rundir import pid_alive
from .campaign_spec import CampaignSpec, Point, expand, load_spec


# --------------------------------------------------------------------------- settings and ledger


def run_settings(config: Config) -> dict:
    """What a run's results depend on: its resolved config without numerics.threads (bitwise
    the same for any thread count) and name (a label)."""
    data = config.to_dict()
    data.pop("name", None)
    data["numerics"] = {k: v for k, v in data["numerics"].items() if k != "threads"}
    return data


def digest(settings: dict) -> str:
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def _diff(old, new, prefix="") -> list[str]:
    """Dotted keys whose values differ between two nested dicts, as 'key: old -> new'."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(old) | set(new), key=str):
            out += _diff(old.get(key), new.get(key), f"{prefix}{key}.")
        return out
    return [] if old == new else [f"{prefix[:-1]}: {old!r} -> {new!r}"]


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
        return "run" if self.kind == "run" else f"fork_{self.slip:03d}"


def _task(ledger: Path, settings: dict, body) -> dict:
    """Run ``body()`` with the piece's ledger kept: running -> done | failed (physics) | error."""
    from ..errors import PhysicsError

    previous = read_ledger(ledger) or {}
    record = {"state": "running", "settings": settings, "host": socket.gethostname(), "pid": os.getpid(),
              "attempts": int(previous.get("attempts", 0)) + 1, "started": time.time()}
    if os.environ.get("SLURM_JOB_ID"):      # a worker started as a SLURM job (--slurm)
        record["slurm_job"] = os.environ["SLURM_JOB_ID"]
    _write_json(ledger, record)
    t0 = time.perf_counter()
    try:
        result = body()
    except PhysicsError as exc:
        record.update(state="failed", cause=f"physics failure: {exc}".splitlines()[0], finished=time.time())
        _write_json(ledger, record)
        return {"state": "failed", "cause": record["cause"]}
    except BaseException as exc:
        record.update(state="error", cause=f"{type(exc).__name__}: {exc}".splitlines()[0])
        _write_json(ledger, record)
        raise
    result["wall_seconds"] = time.perf_counter() - t0
    record.update(state="done", result=result, finished=time.time())
    _write_json(ledger, record)
    return {"state": "done", **result}


def advance_run(run_dir: str, config: dict, settings: dict) -> dict:
    """Dask task: bring the point's run to 'finished'. Resumes from checkpoints/latest.h5 when an
    earlier attempt left one; starts afresh otherwise. Returns the slips kept with checkpoints."""
    from ..io.runfile import run_status, slip_catalog
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
        catalog = slip_catalog(run_dir)
        return {"resumed": resumed, "n_slips": len(catalog),
                "slips": [int(e["number"]) for e in catalog if e.get("checkpoint")]}

    return _task(run_dir / "ledger" / "run.json", settings, body)


def advance_fork(run_dir: str, slip: int, permeabilities: list[float], duration: float | None,
                 settings: dict) -> dict:
    """Dask task: drained + undrained branches of one slip (:func:`gouge_cli.workflows.fork.run_fork`),
    started afresh from the slip checkpoint (any partial branches of a lost attempt are replaced),
    then the fork's pair.json (the one pair definition, :mod:`gouge_cli.workflows.pairs`)."""
    from .fork import ForkRequest, run_fork
    from .pairs import write_pair_json

    run_dir = Path(run_dir)

    def body():
        summary = run_fork(ForkRequest(run_dir, slip, tuple(permeabilities), duration=duration, force=True),
                           quiet=True)
        write_pair_json(RunLayout(run_dir).fork(slip).root)
        return {"branches": {k: b["status"] for k, b in summary["branches"].items()}}

    return _task(run_dir / "ledger" / f"fork_{slip:03d}.json", settings, body)


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
    """Run, then fork every slip kept with a checkpoint at the study's permeabilities. (The per-slip
    step is :func:`advance_fork`; a `gouge study` workflow can replace it here.)"""

    name = "study"

    def after(self, point, piece, result):
        if piece.kind != "run" or result.get("state") != "done":
            return []
        return [Piece(point, "fork", n) for n in result["slips"]]

    def settings(self, piece, run):
        if piece.kind == "run":
            return run
        study = self.spec.study
        return {"run": digest(run), "slip": piece.slip, "permeabilities": list(study.permeabilities),
                "duration": study.duration}


def make_action(spec: CampaignSpec) -> Action:
    return {"run": Action, "study": StudyAction}[spec.action](spec)


# --------------------------------------------------------------------------- survey


@dataclass
class PieceState:
    piece: Piece
    state: str            # done | running | interrupted | failed | left | conflict
    detail: str = ""
    record: dict | None = None


@dataclass
class Survey:
    """Where every piece of a campaign stands, read from the point directories."""

    spec: CampaignSpec
    root: Path
    points: list[Point]
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


def _piece_state(piece: Piece, ledger: Path, settings: dict, output: Path) -> PieceState:
    record = read_ledger(ledger)
    if record is None:
        if output.exists():
            return PieceState(piece, "conflict", f"{output} exists but was not made by this campaign")
        return PieceState(piece, "left")
    old = record.get("settings") or {}
    changed = _diff(old, settings)
    perms_only = piece.kind == "fork" and changed and not _diff(
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
        return PieceState(piece, "conflict", "; ".join(changed), record)
    return PieceState(piece, state, detail, record)


def survey(spec: CampaignSpec, spec_path: Path) -> Survey:
    points = expand(spec, Path(spec_path))
    root = Path(spec.out).resolve() / spec.name
    out = Survey(spec, root, points)
    action = make_action(spec)
    for point in points:
        pdir = root / point.name
        run = run_settings(point.config)
        rs = _piece_state(Piece(point.name, "run"), pdir / "ledger" / "run.json", run, RunLayout(pdir).run_file)
        out.pieces.append(rs)
        if rs.state == "done":
            for piece in action.after(point.name, rs.piece, rs.record.get("result", {}) | {"state": "done"}):
                ledger = pdir / "ledger" / f"{piece.label}.json"
                pair_file = RunLayout(pdir).fork(piece.slip).pair_file
                out.pieces.append(_piece_state(piece, ledger, action.settings(piece, run), pair_file))
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
    """Remove a conflicting piece's results (``--force``): a run takes its forks with it."""
    pdir = s.point_dir(ps.piece.point)
    if ps.piece.kind == "run":
        for name in [n for n in OWNED if n != CONFIG_FILE] + ["ledger"]:
            target = pdir / name
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
    else:
        (pdir / "ledger" / f"{ps.piece.label}.json").unlink(missing_ok=True)


@dataclass
class CampaignReport:
    survey: Survey
    submitted: int
    finished: dict          # state -> count of this invocation's pieces
    wall_seconds: float
    outputs: dict


def run_campaign(spec_path: Path, *, client=None, cluster=None, force: bool = False,
                 retry_failed: bool = False, max_points: int | None = None, log=print) -> CampaignReport:
    """Run what is left of a campaign on Dask and write its table and figures.

    ``client``: a ``distributed.Client`` to use; otherwise one is opened for ``cluster``
    (:class:`~gouge_cli.workflows.executors.ClusterOptions`, default a LocalCluster) only when
    something is left to run. Raises :class:`CampaignConflict` when results exist with other
    settings and ``force`` is not given. ``max_points``: overrides the spec's limit on the sweep's size.
    """
    from .executors import ClusterOptions, open_client

    t_start = time.perf_counter()
    spec_path = Path(spec_path)
    spec = load_spec(spec_path, max_points)
    s = survey(spec, spec_path)
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
    todo_states = {"left", "interrupted", "conflict"} | ({"failed"} if retry_failed else set())
    todo = [p.piece for p in s.pieces if p.state in todo_states]
    busy = s.by_state("running")
    for b in busy:
        log(f"skipping {b.piece.point} {b.piece.label}: already running ({b.detail})")
    finished: dict[str, int] = {}
    if todo:
        opts = cluster or ClusterOptions()
        if client is not None:
            finished = _execute(s, todo, client, opts.retries, log)
        else:
            with open_client(opts) as c:
                finished = _execute(s, todo, c, opts.retries, log)
    s = survey(spec, spec_path)
    outputs = write_results(s, log) if (finished or _results_stale(s)) else {}
    return CampaignReport(s, sum(finished.values()), finished, time.perf_counter() - t_start, outputs)


def _submit(client, s: Survey, piece: Piece, retries: int, token: str):
    point = s.point(piece.point)
    pdir = str(s.point_dir(piece.point))
    action = make_action(s.spec)
    run = run_settings(point.config)
    key = f"gouge-{s.spec.name}-{piece.point}-{piece.label}-{token}"
    if piece.kind == "run":
        return client.submit(advance_run, pdir, point.config.to_dict(), run, key=key, retries=retries, pure=False)
    study = s.spec.study
    return client.submit(advance_fork, pdir, piece.slip, list(study.permeabilities), study.duration,
                         action.settings(piece, run), key=key, retries=retries, pure=False)


def _execute(s: Survey, todo: list[Piece], client, retries: int, log) -> dict[str, int]:
    """Submit the pieces, add the pieces each finished one opens, until none is left."""
    from distributed import as_completed

    action = make_action(s.spec)
    token = os.urandom(3).hex()
    futures = {}
    for piece in todo:
        futures[_submit(client, s, piece, retries, token)] = piece
    done: dict[str, int] = {}
    queue = as_completed(list(futures))
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
        extra = f" ({result['wall_seconds']:.1f} s" + (", resumed" if result.get("resumed") else "") + \
            (f", {len(result['slips'])} slips to fork" if "slips" in result and s.spec.action == "study" else "") + ")" \
            if state == "done" else f": {result.get('cause', '')}"
        log(f"[{n} finished, {len(futures)} queued] {piece.point} {piece.label}: {state}{extra}")
        for nxt in action.after(piece.point, piece, result):
            f = _submit(client, s, nxt, retries, token)
            futures[f] = nxt
            queue.add(f)
    return done


# --------------------------------------------------------------------------- results


def _results_stale(s: Survey) -> bool:
    table = s.root / "table.csv"
    if not table.is_file():
        return bool(s.by_state("done"))
    newest = max((p.record or {}).get("finished", 0) for p in s.pieces) if s.pieces else 0
    return newest > table.stat().st_mtime


def done_points(s: Survey) -> list:
    """The points whose run is done, as analysis.campaign_table.CampaignPoint (swept values, the
    slips whose fork is done, the study's permeabilities): the rows of table.csv and gouge_cli.api."""
    from ..analysis.campaign_table import CampaignPoint

    done_runs = {p.piece.point for p in s.pieces if p.piece.kind == "run" and p.state == "done"}
    forks: dict[str, list[int]] = {}
    for p in s.pieces:
        if p.piece.kind == "fork" and p.state == "done":
            forks.setdefault(p.piece.point, []).append(p.piece.slip)
    swept = [k for k in s.spec.swept_keys()]
    perms = list(s.spec.study.permeabilities) if s.spec.study else []
    return [CampaignPoint(p.name, s.point_dir(p.name), {k: _value(p.config, k) for k in swept},
                          sorted(forks.get(p.name, [])), perms)
            for p in s.points if p.name in done_runs]


def write_results(s: Survey, log=print) -> dict:
    """table.csv (one row per run and per pair), phase_diagram.csv and the figures."""
    from ..analysis.campaign_table import PHASE_COLUMNS, campaign_table, phase_cells, write_table
    from ..plots.phase import pair_histograms, phase_diagram_figure, sweep_figure
    from .campaign_spec import phase_axes

    swept = [k for k in s.spec.swept_keys()]
    rows, pairs_by_perm = campaign_table(done_points(s))
    out = {"table": write_table(rows, swept, s.root / "table.csv")}
    figs = s.root / "figures"
    pair_rows = [r for r in rows if r["kind"] == "pair"]
    if s.spec.action == "study":
        x, y = phase_axes(s.spec)
        cells = phase_cells(pair_rows, x, y)
        out["phase_csv"] = write_table(cells, [], s.root / "phase_diagram.csv", columns=list(PHASE_COLUMNS))
        if cells:
            out["phase_diagram"] = phase_diagram_figure(cells, x, y, figs / "phase_diagram.png", s.spec.name)
        out["pair_histograms"] = pair_histograms(pairs_by_perm, figs)
        for c in cells:
            log(f"phase cell {x}={c['x']:g}" + (f", {y}={c['y']:g}" if y else "") +
                f": {c['n_pairs']} pairs, complex fraction {c['frac_complex']:.3g}, Type II fraction "
                f"{c['frac_type_II']:.3g}")
    if s.spec.action == "study" and len(s.spec.study.permeabilities) >= 2:
        out.update(_regime_outputs(pair_rows, s, figs))
    sweep_keys = [k for k in swept if k != "seed"]
    if sweep_keys:
        out["slip_statistics"] = sweep_figure([r for r in rows if r["kind"] == "run"], sweep_keys,
                                              figs / "slip_statistics.png", s.spec.name)
    return out


def _regime_outputs(pair_rows: list[dict], s: Survey, figs: Path) -> dict:
    """regime.csv, delay.csv and their figures (workflows.regime_report), for a study campaign with
    two permeabilities or more; a campaign that sweeps more than seeds gets one set per value of
    its swept keys, under regime/<key>-<value>_.../ (permeabilities and other swept values are
    never pooled)."""
    from .campaign_spec import point_name
    from .regime_report import by_swept, write_regime

    keys = [k for k in s.spec.swept_keys() if k != "seed"]
    if not keys:
        return write_regime(pair_rows, s.root, figs, s.spec.name)
    out = {}
    for values, rows in by_swept(pair_rows, keys):
        name = point_name(values)
        where = ", ".join(f"{k} = {v}" for k, v in values.items())
        for key, path in write_regime(rows, s.root / "regime" / name, s.root / "regime" / name,
                                      f"{s.spec.name}, {where}").items():
            out[f"{key}[{name}]"] = path
    return out


def _value(config: Config, key: str) -> float:
    """The resolved (dimensionless) value of a dotted config key."""
    node = config.to_dict()
    for part in key.split("."):
        node = node[part]
    return node


__all__ = ["Piece", "Survey", "advance_run", "advance_fork", "survey", "status_lines",
           "run_campaign", "write_results", "done_points", "run_settings", "load_spec"]
