"""`gouge` command line. Exit codes: 0 done, 2 bad input, 3 physics failure or full disk, 4 done with
damaged forks skipped (analyze, study), 130 interrupted."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from ..config import build_config, dump_config, load_config, parse_overrides
from .common import err, fail, guarded, main_event, out
from ..errors import EXIT_INTERRUPTED

__all__ = ["app", "main"]

app = typer.Typer(add_completion=False, no_args_is_help=True, context_settings={"help_option_names": ["-h", "--help"]},
                  rich_markup_mode=None,   # help texts hold units in brackets, e.g. [d^2]: no markup
                  help="gouge: grain-scale stick-slip simulations of (water-saturated) fault gouge.")


def _version(value: bool):
    if value:
        from .. import __version__

        print(f"gouge {__version__}")
        raise typer.Exit()


@app.callback()
def _main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print the version and exit")):
    """gouge: grain-scale stick-slip simulations of (water-saturated) fault gouge."""


@app.command()
@guarded
def run(
    config: Path = typer.Argument(..., help="YAML run config"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output directory (default runs/<name>)"),
    set_: List[str] = typer.Option([], "--set", help="override, e.g. --set loading.velocity=2e-5"),
    force: bool = typer.Option(False, "--force", help="overwrite an existing run directory"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress output"),
    yes: bool = typer.Option(False, "--yes", help="start a run estimated above 1 h without asking (needed "
                             "where no terminal can confirm it)"),
):
    """Compact the packing, then shear it under the spring until config.run.duration."""
    from ..workflows.run import default_run_dir, run_scene
    from .common import confirm_long

    cfg = load_config(config, parse_overrides(set_))
    target = out_dir or default_run_dir(cfg)
    result = run_scene(cfg, target, force=force, quiet=quiet, confirm=confirm_long(yes))
    out.print(f"{result.status}: {result.out_dir} ({result.steps} steps, {result.wall_seconds:.1f} s, "
              f"{result.grain_steps_per_second / 1e6:.2f} M grain-steps/s)", highlight=False)
    _stopped(result)


def _stopped(result):
    """An interrupted run (Ctrl-C, SIGTERM, SIGHUP): one line naming the command that continues it
    (on stderr, --quiet or not), exit 130."""
    if result.status == "interrupted":
        err.print(f"interrupted: the checkpoint is written; `gouge resume {result.out_dir}` continues the run",
                  highlight=False, markup=False)
        raise typer.Exit(EXIT_INTERRUPTED)


def _run_dir(run_dir: Optional[Path]) -> Path:
    from ..io.rundir import check_run_dir, latest_run

    return check_run_dir(run_dir) if run_dir else latest_run()


@app.command()
@guarded
def restart(
    run_dir: Optional[Path] = typer.Argument(None, help="run directory (default: the latest under runs/)"),
    slip: int = typer.Option(..., "--slip", help="slip number (see `gouge slips RUN`)"),
    perm: List[float] = typer.Option([], "--perm", help="kappa_c [d^2] of an undrained branch; repeatable"),
    set_: List[str] = typer.Option([], "--set", help="override key=value for both branches"),
    duration: Optional[float] = typer.Option(None, "--duration", help="run each branch this long [t0]"),
    until_slip_ends: bool = typer.Option(True, "--until-slip-ends/--full",
                                         help="stop each branch when its first slip ends (default)"),
    force: bool = typer.Option(False, "--force", help="run an existing branch of the same permeability (and "
                               "the drained branch) again; without it, --perm K adds branch K to an existing fork"),
    main: str = typer.Option("first", "--main", callback=main_event, help="compared event of each branch in "
                             "pair.json: first (the forked slip) or largest"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress output"),
    as_json: bool = typer.Option(False, "--json", help="print the whole record (branches and pairs) as JSON"),
):
    """Fork drained and undrained branches from the packing kept just before slip N (no --perm:
    the drained branch alone); with --perm, writes pair.json. On a slip forked before, --perm K adds
    the branch K (the finished drained branch is kept). Times printed in t0 since loading began."""
    import json

    from ..io.filedoc import json_safe
    from ..workflows.fork import ForkRequest, restart as run_restart
    from .common import restart_lines

    target = _run_dir(run_dir)
    if duration is None and not until_slip_ends:
        fail("--full needs --duration")
    request = ForkRequest(target, slip, tuple(perm), parse_overrides(set_), duration, force=force, main=main)
    summary = run_restart(request, quiet=quiet)
    if as_json:
        out.print(json.dumps(json_safe(summary.to_dict()), indent=2, allow_nan=False), highlight=False)
        return
    for line in restart_lines(summary, target):
        out.print(line, highlight=False, markup=False)


@app.command()
@guarded
def resume(
    run_dir: Optional[Path] = typer.Argument(None, help="run directory (default: the latest under runs/)"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress output"),
):
    """Continue an interrupted run (Ctrl-C, kill -9, power loss) from its latest checkpoint."""
    from ..io.layout import RunLayout
    from ..io.runreader import run_status
    from ..workflows.run import resume_run

    target = _run_dir(run_dir)
    if run_status(RunLayout(target).run_file) == "finished":
        out.print(f"{target} finished already: nothing to resume", highlight=False)
        return
    result = resume_run(target, quiet=quiet)
    out.print(f"{result.status}: {result.out_dir} ({result.steps} steps, {result.wall_seconds:.1f} s)",
              highlight=False)
    _stopped(result)


@app.command()
@guarded
def slips(
    run_dir: Optional[Path] = typer.Argument(None, help="run directory (default: the latest under runs/)"),
    as_json: bool = typer.Option(False, "--json", help="machine-readable output"),
    wide: bool = typer.Option(False, "--wide", help="one table at its full width, past the terminal's edge if need be "
                          "(default: split to fit)"),
):
    """List the slips detected in a run (the catalog written while it ran)."""
    import json

    from ..io.rundir import refuse_if_in_progress

    from .export_cmds import catalog_since_loading

    target = _run_dir(run_dir)
    refuse_if_in_progress(target, "slips")
    catalog, origin = catalog_since_loading(target)
    if as_json:
        print(json.dumps(catalog, allow_nan=False))
        return
    from rich.markup import escape

    from ..io.runreader import RunReader
    from ..units import ResultUnits
    from .analysis_cmds import _table

    with RunReader(target, allow_running=True) as reader:
        info = reader.info
        units = ResultUnits.of_run(info.config, info.V_s, info.sigma)
    for e in catalog:
        for key, scale, si in (("onset_time", units.t0_s * 1e3, "onset_time_ms"),
                               ("duration", units.t0_s * 1e6, "duration_us"),
                               ("peak_velocity_over_Vs", units.V_s_m_s, "peak_velocity_m_s"),
                               ("stress_drop", units.sigma_MPa, "stress_drop_MPa")):
            e[si] = e[key] * scale if e.get(key) is not None else None
    out.print(escape(f"slips of {target}: times in t0 since loading began (stored clock − {origin:.6g} t0); "
                     f"{units.caption()}"), highlight=False)
    cols = [("number", "#"), ("onset_time", "onset [t0]"), ("onset_time_ms", "onset [ms]"),
            ("duration", "duration [t0]"), ("duration_us", "duration [µs]"), ("static_strength", "τs/σ"),
            ("stress_drop", "Δτ/σ"), ("stress_drop_MPa", "Δτ [MPa]"), ("peak_velocity_over_Vs", "v_peak/V_s"),
            ("peak_velocity_m_s", "v_peak [m/s]"), ("slip", "slip [d]"), ("checkpoint", "checkpoint")]
    out.print(_table(f"slips ({len(catalog)})", cols, catalog, wide=wide, digits=5))


@app.command("config")
@guarded
def show_config(
    config: Optional[Path] = typer.Argument(None, help="YAML config to validate and print resolved"),
    set_: List[str] = typer.Option([], "--set", help="override key=value"),
    defaults: bool = typer.Option(False, "--defaults", help="print every key with its default, unit, range and "
                                  "meaning (commented YAML)"),
    schema: Optional[Path] = typer.Option(None, "--schema", help="write the JSON Schema of a config to this file "
                                          "('-' for stdout), for editors"),
):
    """Validate a config and print it fully resolved (dimensionless), or print the defaults."""
    from ..model.scene import Scene
    from ..model.timestep import stability_bound

    if schema is not None or (defaults and config is None and not set_):
        from .export_cmds import print_config_doc

        print_config_doc(schema)
        return
    sets = parse_overrides(set_)
    cfg = build_config({}, sets) if (defaults or config is None) else load_config(config, sets)
    bound = stability_bound(cfg)
    pre = Scene(cfg).preflight
    out.print(dump_config(cfg), highlight=False, end="")
    out.print(f"# time step {pre.dt:.6g} t0 (stability bound {bound.bound:.6g} t0, {bound.mode} mode)",
              highlight=False)
    for line in (pre.note, pre.warning):
        if line:
            out.print(f"# {line}", highlight=False)


@app.command()
def bench(
    sizes: str = typer.Option("2500,10000,40000,160000", help="comma-separated grain counts"),
    threads: str = typer.Option("", help="comma-separated thread counts (default: 1 and all cores)"),
    steps: int = typer.Option(5000, help="timed steps per repeat at <= 10,000 grains (fewer above, "
                              "for about the same time per repeat)"),
    repeats: int = typer.Option(3, help="repeats (min/median/max reported)"),
    dt: float = typer.Option(0.89, help="time step [t0] (LAMMPS deck default)"),
    skin: float = typer.Option(0.2, help="Verlet skin [d]"),
    lammps: bool = typer.Option(True, help="also time LAMMPS (the deck in benchmarks/lammps) where lmp is "
                                "installed; says why when it cannot"),
    lammps_max: int = typer.Option(40000, help="largest N timed in LAMMPS (its set-up of 160,000 grains "
                                   "takes about 20 minutes)"),
    perm: float = typer.Option(1e-5, "--perm", help="also time the undrained 10,000-grain scene (implicit "
                               "fluid, this kappa_c [d^2]) and report the fluid share of a step; 0 to skip"),
    profile: bool = typer.Option(True, help="time each part of a step"),
    cache: Path = typer.Option(Path("runs/bench/cache"), help="folder for pre-sheared states ('' for none)"),
    json_out: Path = typer.Option(Path("runs/bench/bench.json"), "--json", help="where to write the JSON results"),
):
    """Grain-steps per second on the sheared layer (steady shear only), 1 and all cores, vs LAMMPS;
    per-part profile, allocations per step, fluid share, projected thesis Run 24 wall times."""
    from ..studies.bench import run_benchmark, write_results
    from ..studies.bench_report import bench_report

    size_list = [int(v) for v in sizes.split(",") if v]
    thread_list = [int(v) for v in threads.split(",") if v] or None
    result = run_benchmark(size_list, thread_list, steps, repeats, dt, skin, lammps, permeability=perm or None,
                           lammps_max=lammps_max, cache=cache if str(cache) else None, profile=profile)
    write_results(result, json_out)
    for item in bench_report(result, json_out):
        out.print(item, highlight=False)


from .analysis_cmds import register as _register_analysis
_register_analysis(app)
from .accuracy_cmds import register as _register_accuracy
_register_accuracy(app)
from .export_cmds import register as _register_export
_register_export(app)
from .campaign_cmds import register as _register_campaign
_register_campaign(app)
from .study_cmds import register as _register_study
_register_study(app)
from .verify_cmds import register as _register_verify; _register_verify(app)  # noqa: E402, E702
from .dilatancy_cmds import register as _register_dilatancy; _register_dilatancy(app)  # noqa: E402, E702


def main():
    app()
