"""Where every piece of a campaign stands, read from its point folders' ledgers and its results
records (:func:`survey`; `gouge campaign --status`: :func:`status_lines`)."""

from __future__ import annotations

import socket
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from ..io.layout import RunLayout
from ..io.rundir import pid_alive
from .campaign_results import RUN_PIECE, PieceRecord, Results, diff_keys, settings_digest
from .campaign_spec import CampaignSpec, Point, expand
from .campaign_tasks import Piece, make_action, read_ledger, run_settings


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
