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
study's permeabilities" (campaign_tasks: advance_run, advance_fork). A run piece whose worker
was lost resumes from ``checkpoints/latest.h5`` (at most one ``output.checkpoint_interval`` of
work is repeated); a fork piece starts again from its slip checkpoint (forks are short). What a
point does is an Action (campaign_tasks); ``study`` = run, then fork every slip kept with a checkpoint.

A campaign finishes points before it starts new ones: at most as many points are in flight as
the cluster has task slots, and a point's forks go before any new loading. Each finished piece
writes its results record before its ledger says done. A piece whose record holds the settings
it would run with is done, whether or not its run folder is still there; a point whose forks are
not all recorded and whose run folder is gone runs its loading again (bitwise the same: the
record's final state hash is compared) and then only the missing forks.

One job a module: the sweep's points (campaign_spec.py), the pieces and their Dask tasks
(campaign_tasks.py), where each piece stands (campaign_survey.py), the results records
(campaign_results.py), the tables and figures (campaign_tables.py), where the tasks run
(executors.py); this module runs what is left of a campaign (:func:`run_campaign`).
"""

from __future__ import annotations

import math
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from ..driver.progress import format_eta
from ..errors import CampaignConflict
from ..config import Config
from ..io.layout import CONFIG_FILE, OWNED, RunLayout
from .campaign_results import PieceRecord
from .campaign_spec import Point, load_spec
from .campaign_survey import PieceState, Survey, survey
from .campaign_tables import results_stale, write_results
from .campaign_tasks import (VARIANTS, RecordTarget, advance_fork, advance_run, fork_result, make_action, read_ledger,
                             run_result, run_settings, study_variants, write_json)


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
    outputs = write_results(s, log) if (finished or results_stale(s)) else {}
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
                      **fork_result(pdir, ps.piece.slip, list(s.spec.study.permeabilities), study_variants(s.spec))}
        record = PieceRecord(s.spec.name, point.name, ps.piece.label, ps.record["settings"], result,
                             wall_seconds=float(ps.record.get("result", {}).get("wall_seconds", 0.0)),
                             finished=float(ps.record.get("finished", time.time())),
                             cpu_seconds=float(ps.record.get("result", {}).get("cpu_seconds", 0.0)))
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
                                                        study_variants(s.spec))}
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
                         action.settings(piece, run), target, study_variants(s.spec), key=key, retries=retries,
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
            write_json(ledger, record)
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


def _value(config: Config, key: str) -> float:
    """The resolved (dimensionless) value of a dotted config key."""
    node = config.to_dict()
    for part in key.split("."):
        node = node[part]
    return node
