"""`gouge study`: the thesis's drained-versus-undrained study in one command (Sections 4.1-4.3).

Steps (each skipped when its output is already there, so the study is idempotent and resumable):

1. The dry loading run: a config is run into ``runs/<name>`` (or ``--out``); a run left
   'interrupted' or 'running' is resumed; a finished run, or a run directory given directly,
   is used as it is.
2. Slips: every non-transient slip with a checkpoint (:func:`~gouge_cli.analysis.study.transient_slips`),
   or the ``--slips`` range.
3. Branches: drained and one undrained branch per ``--perm`` of every slip, all with the same
   window (:func:`study_window`); with ``--main first`` a branch stops as soon as its first slip
   (at the trigger) ends, with ``--main largest`` it runs the whole window. Independent tasks (:func:`branch_task`) in a process pool
   with one numba thread each, whose workers end when the study's process dies (:mod:`.watchdog`). A branch whose ``run.h5`` has status 'finished' is skipped; any
   other (interrupted, running, failed, missing) is run again from the slip's checkpoint
   (branches write no checkpoints of their own). A new ``--perm`` adds only its branches.
4. ``pair.json`` per fork, ``RUN/analysis`` (``gouge analyze``), and ``RUN/study``:
   ``table.csv`` (one row per pair, thesis Table 3 / Appendix B), ``summary.json``,
   ``report.md`` (the summary next to the thesis's numbers) and ``figures/``.
"""

from __future__ import annotations

import errno
import json
import math
import multiprocessing
import os
import shlex
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from ..analysis.pairs import MainEvent
from ..analysis.report import analyze_run, write_analysis
from ..analysis.study import (STUDY_COLUMNS, StudyGroup, StudyRow, study_rows, study_summaries, summary_lines,
                              transient_slips, write_study_table)
from ..io.checkpoint import read_checkpoint
from ..config import load_config
from ..errors import ConfigError, NoSpaceError, StudyInterrupted
from ..io.slipcatalog import SlipEntry, slip_catalog
from .fork import check_perms, run_branch
from ..errors import RunDirError
from ..io.layout import RunLayout, branch_name, perm_text, slip_name
from ..io.rundir import check_run_dir
from .run import default_run_dir, resume_run, run_scene
from ..io.filedoc import json_safe
from ..io.records import plain, unit
from .pairs import branch_status, write_pair_json
from .watchdog import follow_parent

__all__ = ["EXTRA_STRENGTH", "BranchRun", "StudyResult", "parse_slips", "study_window", "branch_task", "plan_branches",
           "run_study"]

#: Each branch runs on after the drained slip's end for 2 slip durations plus the time the spring
#: needs to add EXTRA_STRENGTH to tau/sigma, so an undrained twin up to that much stronger (Type II;
#: the thesis's Fig. 10 twin is ~0.05 stronger) still fails inside the window.
EXTRA_STRENGTH = 0.05


def parse_slips(text: str | None) -> list[int] | None:
    """``"3-12"``, ``"3,5,7"`` or ``"3-5,9"`` -> sorted slip numbers; None for None. ValueError if malformed."""
    if not text:
        return None
    out = set()
    for part in text.split(","):
        part = part.strip()
        if "-" in part:
            a, b = (int(x) for x in part.split("-", 1))
            if b < a:
                raise ValueError(f"--slips {text!r}: range {part} runs backwards")
            out.update(range(a, b + 1))
        elif part:
            out.add(int(part))
    return sorted(out)


def study_window(entry: SlipEntry, checkpoint_time: float, sigma: float, k: float, V_s: float) -> float:
    """Duration [t0] of every branch of one slip, from its checkpoint:
    ``(end - t_ck) + 2 duration + EXTRA_STRENGTH sigma / (k V_s)``."""
    end, duration = entry.end_time, entry.duration
    return (end - checkpoint_time) + 2.0 * duration + EXTRA_STRENGTH * sigma / (k * V_s)


def _one_thread():
    os.environ["NUMBA_NUM_THREADS"] = "1"


def _pool_worker(parent_pid: int):
    """Initializer of the pool's workers: one numba thread, and the worker ends with the study
    (:func:`~gouge_cli.workflows.watchdog.follow_parent`: no orphans when the study is killed)."""
    follow_parent(parent_pid)
    _one_thread()


@dataclass(frozen=True)
class BranchRun:
    """What :func:`branch_task` reports of one branch it ran (picklable)."""

    slip: int = unit("-", "slip number the branch forks before")
    branch: str = unit("-", "drained or perm_K")
    status: str = unit("-", "the branch's status: finished, interrupted, or failed/physics failure with its message")
    steps: int = unit("-", "time steps run")
    wall_seconds: float = unit("s", "wall-clock time it took")


def branch_task(run_dir: str, slip: int, perm: float | None, duration: float,
                stop_after_slip: bool = True) -> BranchRun:
    """The per-fork step: run one branch of one slip (fresh) and report it. Picklable arguments and
    result, one numba thread, so any executor (this process pool, a Dask cluster) can call it."""
    _one_thread()
    import numba

    from ..errors import PhysicsError

    numba.set_num_threads(1)
    t0 = time.perf_counter()
    try:
        r = run_branch(Path(run_dir), slip, perm, duration, quiet=True, stop_after_slip=stop_after_slip)
        status, steps = r.status, r.steps
    except PhysicsError as exc:
        status, steps = f"physics failure: {exc}", 0
    return BranchRun(slip, branch_name(perm), status, steps, time.perf_counter() - t0)


@dataclass(frozen=True)
class StudyResult:
    """What :func:`run_study` ran, skipped and found; ``study/summary.json`` is
    :meth:`summary_record`."""

    run_dir: Path = unit("-", "the loading run")
    slips: list[int] = unit("-", "the slips studied")
    transient: list[int] = unit("-", "the run's transient slips (left out of the statistics)")
    perms: list[float] = unit("d^2", "kappa_c of the undrained branches")
    main: str = unit("-", "compared event: first or largest")
    loading: str = unit("-", "what step 1 did: given, done before, resumed (status), ran")
    ran: list[BranchRun] = unit("-", "branches run now", default_factory=list)
    skipped: list[str] = unit("-", "branches finished before ('slip N branch')", default_factory=list)
    damaged: list[str] = unit("-", "forks left out of the tables (analysis.skipped)", default_factory=list)
    rows: list[StudyRow] = unit("-", "the study table", default_factory=list)
    summary: list[StudyGroup] = unit("-", "one summary per permeability, in increasing kappa_c",
                                     default_factory=list)
    written: dict = unit("-", "{what: path} of the files written", default_factory=dict)

    def summary_record(self) -> dict:
        """``study/summary.json``: the study's choices, each permeability's summary and the same
        side by side with the thesis."""
        return {"run": str(Path(self.run_dir).resolve()), "perms": list(self.perms), "main": self.main,
                "slips": self.slips, "transient_slips": self.transient,
                "per_permeability": [g.to_dict() for g in self.summary],
                "side_by_side": {perm_text(g.permeability): [list(x) for x in summary_lines(g.summary)]
                                 for g in self.summary}}


def _loading_run(target: Path, out: Path | None, overrides: dict | None, quiet: bool,
                 confirm=None) -> tuple[Path, str]:
    """Step 1: the run directory, running or resuming the loading run when needed."""
    target = Path(target)
    if target.is_dir():
        return check_run_dir(target), "given"
    cfg = load_config(target, overrides)
    run_dir = Path(out) if out is not None else default_run_dir(cfg)
    h5 = RunLayout(run_dir).run_file
    if h5.is_file():
        status = branch_status(run_dir)
        if status == "finished":
            return run_dir, "done before"
        if RunLayout(run_dir).latest.is_file():
            _finished(resume_run(run_dir, quiet=quiet), run_dir)
            return run_dir, f"resumed ({status})"
    _finished(run_scene(cfg, run_dir, force=h5.is_file(), quiet=quiet, confirm=confirm), run_dir)
    return run_dir, "ran"


def _finished(result, run_dir: Path) -> None:
    if result.status == "interrupted":
        raise StudyInterrupted(f"the loading run {run_dir} was interrupted; run `gouge study` again to resume it")


def plan_branches(run_dir: Path, slips: list[int], perms: list[float]) -> tuple[list[tuple], list[str]]:
    """Step 3's work list: ``(slip, perm, duration)`` for every branch not yet 'finished'; and the
    names of those skipped as done."""
    catalog = {e.number: e for e in slip_catalog(run_dir)}
    todo, done = [], []
    for slip in slips:
        entry = catalog[slip]
        ck = read_checkpoint(run_dir / entry.checkpoint)
        cfg = ck.config
        window = study_window(entry, ck.time, cfg.loading.normal_stress, cfg.loading.spring_constant,
                              cfg.loading.velocity)
        for perm in [None, *perms]:
            branch = RunLayout(run_dir).fork(slip).branch(perm).root
            if branch_status(branch) == "finished":
                done.append(f"slip {slip} {branch.name}")
            else:
                todo.append((slip, perm, window))
    return todo, done


def _select(run_dir: Path, wanted: list[int] | None) -> tuple[list[int], set[int]]:
    catalog = slip_catalog(run_dir)
    if not catalog:
        raise RunDirError(f"{run_dir} has no slips yet: run it longer (run.duration) before a study")
    transient = transient_slips(catalog)
    with_ck = [e.number for e in catalog if e.checkpoint]
    if wanted is None:
        return [n for n in with_ck if n not in transient], transient
    missing = [n for n in wanted if n not in with_ck]
    if missing:
        raise RunDirError(f"--slips: {run_dir} has no checkpoint for slip(s) {', '.join(map(str, missing))}; "
                          f"slips with checkpoints: {', '.join(map(str, with_ck)) or 'none'}")
    return wanted, transient


def run_study(target: Path, perms: list[float], slips: list[int] | None = None, main: str = "first",
              jobs: int | None = None, out: Path | None = None, overrides: dict | None = None,
              quiet: bool = False, figures: bool = True, on_progress=None, confirm=None) -> StudyResult:
    """Run steps 1-4 (see the module docstring); returns what was run, skipped and found.
    ``confirm``: asked before a long loading run starts (:func:`~gouge_cli.workflows.run.run_scene`)."""
    if not perms:
        raise ConfigError("give at least one --perm K (kappa_c in d^2, e.g. --perm 1e-5)")
    check_perms(perms)
    main = MainEvent.check(main)
    say = on_progress or (lambda msg: None)
    run_dir, how = _loading_run(target, out, overrides, quiet, confirm)
    say(f"loading run {run_dir}: {how}")
    chosen, transient = _select(run_dir, slips)
    todo, skipped = plan_branches(run_dir, chosen, perms)
    ran = []
    say(f"{len(chosen)} slips, {len(todo)} branches to run, {len(skipped)} done before")
    if todo:
        workers = max(1, min(jobs or os.cpu_count() or 1, len(todo)))
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_pool_worker,
                                 initargs=(os.getpid(),)) as pool:
            futures = [pool.submit(branch_task, str(run_dir), s, p, w, main == "first") for s, p, w in todo]
            for fut in as_completed(futures):
                try:
                    rec = fut.result()
                except OSError as exc:
                    if exc.errno != errno.ENOSPC:
                        raise
                    for other in futures:
                        other.cancel()
                    command = shlex.join(["gouge", "study", str(run_dir), *[a for k in perms for a in ("--perm", perm_text(k))],
                                          "--slips", ",".join(map(str, chosen)), "--main", main])
                    raise NoSpaceError(exc.filename or str(run_dir), f"run `{command}` again (the branches that "
                                       "finished are kept)", getattr(exc, "need", None),
                                       getattr(exc, "detail", "")) from None
                ran.append(rec)
                say(f"slip {rec.slip} {rec.branch}: {rec.status} ({rec.wall_seconds:.0f} s)")
    for slip in chosen:
        try:
            write_pair_json(RunLayout(run_dir).fork(slip).root, main)
        except Exception as exc:       # a failed branch: the pair is reported as skipped below
            say(f"slip {slip}: no pair ({exc})")
    analysis = analyze_run(run_dir, main=main)
    damaged = [r for r in analysis.skipped if getattr(r, "damaged", True)
               and any(slip_name(s) in r for s in chosen)]
    written = dict(write_analysis(analysis))
    pairs = [p for p in analysis.pairs if int(p.slip) in set(chosen)
             and p.branch in {branch_name(k) for k in perms}]
    rows = study_rows(run_dir, pairs, transient)
    result = StudyResult(run_dir, chosen, sorted(transient), list(perms), main, how, ran, skipped, damaged, rows,
                         study_summaries(rows), written)
    written.update(_write_study(result, pairs if figures else None))
    return result


def _write_study(result: StudyResult, pairs) -> dict:
    run_dir, perms, main = result.run_dir, result.perms, result.main
    out = run_dir / "study"
    out.mkdir(parents=True, exist_ok=True)
    table = out / "table.csv"
    write_study_table(table, result.rows)
    (out / "summary.json").write_text(json.dumps(json_safe(result.summary_record()), indent=2, allow_nan=False))
    lines = [f"# Study of {run_dir}", "", f"kappa_c: {', '.join(perm_text(p) for p in perms)}; compared events: "
             f"{main}; slips {', '.join(map(str, result.slips))}; transient (left out): "
             f"{', '.join(map(str, result.transient)) or 'none'}", "",
             "Permeabilities are never pooled: one summary per kappa_c.", ""]
    for g in result.summary:
        lines += [f"## kappa_c = {perm_text(g.permeability)} d^2 "
                  f"({', '.join(f'{k} {v}' for k, v in g.regimes.items())})", "",
                  "| quantity | this study | thesis |", "|---|---|---|"]
        lines += [f"| {a} | {b} | {c} |" for a, b, c in summary_lines(g.summary)]
        lines.append("")
    lines += ["", "| " + " | ".join(STUDY_COLUMNS[:-1]) + " |", "|" + "---|" * (len(STUDY_COLUMNS) - 1)]
    for r in map(plain, result.rows):
        lines.append("| " + " | ".join(_cell(r[c]) for c in STUDY_COLUMNS[:-1]) + " |")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    written = {"study_table": table, "study_summary": out / "summary.json", "study_report": out / "report.md"}
    if pairs is not None:
        from ..plots.study import study_figures

        written["study_figures"] = study_figures(run_dir, pairs, result.rows, out / "figures")
    return written


def _cell(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return "–" if not math.isfinite(v) else f"{v:.4g}"
    return str(v)
