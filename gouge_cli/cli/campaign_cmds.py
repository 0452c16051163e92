"""`gouge campaign`: thin wrapper over gouge_cli.workflows.campaign (registered from cli/main.py).

Exit codes: 0 every piece done, 2 bad spec / changed settings without --force / bad cluster
option, 3 some piece failed (physics failure or a worker lost too often; see --status),
130 interrupted (run it again to resume).
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer


def register(app: typer.Typer):
    from ..errors import EXIT_INTERRUPTED, EXIT_PHYSICS
    from .common import guarded, out

    @app.command()
    @guarded
    def campaign(
        spec: Path = typer.Argument(..., help="campaign file (YAML: name, base, set, sweep, action, study, phase)"),
        status: bool = typer.Option(False, "--status", help="show what is done, running, failed and left; run nothing"),
        tables: bool = typer.Option(False, "--tables", help="write the tables and figures from the results records; "
                                    "run nothing"),
        reanalyse: bool = typer.Option(False, "--reanalyse", help="with --tables: first analyse again, with this "
                                       "gouge, every recorded piece whose run folder is here, and rewrite its record"),
        merge: Optional[Path] = typer.Option(None, "--merge", help="copy in the results records of another results "
                                             "folder of this spec (refused, naming the key, where settings differ); "
                                             "run nothing"),
        force: bool = typer.Option(False, "--force", help="run again the pieces whose settings changed (old results deleted)"),
        retry_failed: bool = typer.Option(False, "--retry-failed", help="run failed pieces again"),
        threads: int = typer.Option(1, "--threads", help="numba threads per task"),
        tasks_per_worker: int = typer.Option(1, "--tasks-per-worker",
                                             help="tasks at a time per worker process (they share its GIL)"),
        workers: Optional[int] = typer.Option(None, "--workers",
                                              help="local worker processes (default: cores // threads)"),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="use an existing Dask scheduler, tcp://HOST:PORT (start its workers as "
                                                       "NUMBA_NUM_THREADS=T dask worker ADDRESS --nthreads 1)"),
        slurm: bool = typer.Option(False, "--slurm", help="start workers as SLURM jobs (needs dask-jobqueue: the 'cluster' extra of gouge)"),
        slurm_cores: int = typer.Option(16, "--slurm-cores", help="cores per SLURM job"),
        slurm_memory: str = typer.Option("32GB", "--slurm-memory", help="memory per SLURM job"),
        slurm_walltime: str = typer.Option("24:00:00", "--slurm-walltime", help="walltime per SLURM job"),
        slurm_queue: Optional[str] = typer.Option(None, "--slurm-queue", help="SLURM partition"),
        slurm_account: Optional[str] = typer.Option(None, "--slurm-account", help="SLURM account"),
        slurm_jobs: int = typer.Option(1, "--slurm-jobs", help="SLURM jobs to start"),
        slurm_extra: List[str] = typer.Option([], "--slurm-directive", help="extra #SBATCH directive; repeatable"),
        retries: int = typer.Option(3, "--retries", help="Dask retries of a piece that raised"),
        max_points: Optional[int] = typer.Option(None, "--max-points", help="refuse a sweep of more points than "
                                                 "this (default: the spec's max_points, 10,000 unless set)"),
    ):
        """Run a parameter sweep (runs, or studies = run + forks of every slip) on Dask; idempotent."""
        from ..workflows.campaign import run_campaign
        from ..workflows.campaign_survey import results_root, status_lines, survey
        from ..workflows.campaign_results import Results, merge as merge_results
        from ..workflows.campaign_spec import load_spec
        from ..workflows.executors import ClusterOptions

        try:
            if merge is not None:
                loaded = load_spec(spec, max_points)
                written = merge_results(Results(results_root(loaded)), Results(merge), loaded.name)
                out.print(f"{len(written)} results records copied from {merge} into {results_root(loaded)}; "
                          f"`gouge campaign {spec} --tables` writes the tables", highlight=False)
                return
            if tables or reanalyse:
                report = run_campaign(spec, max_points=max_points, tables_only=True, reanalysed=reanalyse,
                                      log=lambda m: out.print(m, highlight=False))
                for line in status_lines(report.survey):
                    out.print(line, highlight=False)
                for name, path in report.outputs.items():
                    out.print(f"{name}: {path}", highlight=False, markup=False)
                return
            if status:
                for line in status_lines(survey(load_spec(spec, max_points), spec)):
                    out.print(line, highlight=False)
                return
            opts = ClusterOptions(threads, tasks_per_worker, workers, scheduler, slurm, slurm_cores, slurm_memory,
                                  slurm_walltime, slurm_queue, slurm_account, slurm_jobs, list(slurm_extra),
                                  retries).check()
            report = run_campaign(spec, cluster=opts, force=force, retry_failed=retry_failed, max_points=max_points,
                                  log=lambda m: out.print(m, highlight=False))
        except KeyboardInterrupt:
            out.print("interrupted: run the same command again to resume (finished pieces are kept)")
            raise typer.Exit(EXIT_INTERRUPTED)
        for line in status_lines(report.survey):
            out.print(line, highlight=False)
        for name, path in report.outputs.items():
            out.print(f"{name}: {path}", highlight=False, markup=False)
        out.print(f"{report.submitted} pieces run in {report.wall_seconds:.1f} s", highlight=False)
        if report.survey.by_state("failed"):
            raise typer.Exit(EXIT_PHYSICS)

    @app.command()
    @guarded
    def regime(
        inputs: List[str] = typer.Argument(..., help="[LABEL=]PATH, one or more: a pair table (a campaign's "
                                           "table.csv or a pairs.csv: rows of kind 'pair'), or a campaign file "
                                           "(its results records; one map per variant and swept value). Several "
                                           "inputs are never pooled: their groups are drawn on one set of axes "
                                           "(groups.png, groups.csv), each under LABEL (default: the file's name)"),
        out_dir: Path = typer.Option(..., "--out", help="folder for regime.csv, delay.csv, regime_map.png and regime_delay.png"),
        title: str = typer.Option("", "--title", help="title line of the figures"),
        where: List[str] = typer.Option([], "--where", help="KEY=VALUE: only the pairs whose swept column KEY holds "
                                        "VALUE (e.g. packing.n_grains=3640); repeatable; with several inputs, an "
                                        "input without column KEY is kept whole (e.g. variant=w3)"),
    ):
        """Write the regime map (per seed, pooled, seed-level and per-pair intervals) and the onset-delay
        view from tables of pairs; nothing is simulated."""
        from ..errors import InputError
        from ..workflows.campaign_tables import read_sources
        from ..workflows.regime_report import select_sources, write_regime, write_sources

        conditions = {}
        for item in where:
            key, sep, value = item.partition("=")
            if not sep or not key.strip():
                raise InputError(f"--where {item!r}: give KEY=VALUE, e.g. loading.normal_stress=3e-4")
            conditions[key.strip()] = value.strip()
        sources = select_sources(read_sources(inputs), conditions)
        if len(sources) == 1 and not sources[0].keys:
            written = write_regime(sources[0].rows, out_dir, out_dir, title)
        else:
            written = write_sources(sources, out_dir, title)
        for name, path in written.items():
            out.print(f"{name}: {path}", highlight=False, markup=False)
