"""The pieces of a campaign and their Dask tasks (the workers' side): a piece's settings and ledger
record, :func:`advance_run` and :func:`advance_fork` (each writes its results record before its
ledger says done), the study variants' folders, and the :class:`Action` that says which pieces a
finished piece opens."""

from __future__ import annotations

import json
import os
import shutil
import socket
import time
from dataclasses import dataclass
from pathlib import Path

from ..config import Config, build_config
from ..io.layout import ForkLayout, RunLayout
from ..model.fluid import COUPLING_REVISION
from .campaign_results import RUN_PIECE, PieceRecord, Results, fork_piece, settings_digest
from .campaign_spec import CampaignSpec


def run_settings(config: Config) -> dict:
    """What a run's results depend on: its resolved config without numerics.threads (bitwise
    the same for any thread count) and name (a label)."""
    data = config.to_dict()
    data.pop("name", None)
    data["numerics"] = {k: v for k, v in data["numerics"].items() if k != "threads"}
    return data


digest = settings_digest      # the settings' hash (campaign_results owns it)


def write_json(path: Path, data: dict):
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

    def write(self, piece: str, settings: dict, result: dict, wall_seconds: float, cpu_seconds: float = 0.0) -> Path:
        return Results(self.results).write(PieceRecord(self.campaign, self.point, piece, settings, result,
                                                       wall_seconds=wall_seconds, cpu_seconds=cpu_seconds))


def _task(ledger: Path, settings: dict, body, record=None) -> dict:
    """Run ``body()`` with the piece's ledger kept: running -> done | failed (physics) | error.
    ``record(result, wall_seconds, cpu_seconds)``: writes the piece's results record, before the ledger
    says done (cpu_seconds: the worker process's CPU time over the piece, what it costs a core
    whatever else shares the machine)."""
    from ..errors import PhysicsError

    previous = read_ledger(ledger) or {}
    entry = {"state": "running", "settings": settings, "host": socket.gethostname(), "pid": os.getpid(),
             "attempts": int(previous.get("attempts", 0)) + 1, "started": time.time()}
    if os.environ.get("SLURM_JOB_ID"):      # a worker started as a SLURM job (--slurm)
        entry["slurm_job"] = os.environ["SLURM_JOB_ID"]
    write_json(ledger, entry)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        result = body()
    except PhysicsError as exc:
        entry.update(state="failed", cause=f"physics failure: {exc}".splitlines()[0], finished=time.time())
        write_json(ledger, entry)
        return {"state": "failed", "cause": entry["cause"]}
    except BaseException as exc:
        entry.update(state="error", cause=f"{type(exc).__name__}: {exc}".splitlines()[0])
        write_json(ledger, entry)
        raise
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if record is not None:
        record(result, wall, cpu)
    result["wall_seconds"] = wall
    result["cpu_seconds"] = cpu
    entry.update(state="done", result=result, finished=time.time())
    write_json(ledger, entry)
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

    def record(result, wall, cpu):
        if target is not None:
            target.write(RUN_PIECE, settings, {"values": target.values, **result}, wall, cpu)

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

    def record(result, wall, cpu):
        if target is not None:
            target.write(fork_piece(slip), settings, {"slip": slip, **result}, wall, cpu)

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
               "duration": study.duration, "coupling": COUPLING_REVISION}
        if study.variants:
            out["variants"] = study.variants
        return out


def make_action(spec: CampaignSpec) -> Action:
    return {"run": Action, "study": StudyAction}[spec.action](spec)


def study_variants(spec: CampaignSpec) -> list[tuple[str, dict]] | None:
    """The study's variants as (name, fork overrides), or None without variants."""
    study = spec.study
    return list(study.variants.items()) if study and study.variants else None
