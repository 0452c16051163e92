"""`gouge accuracy`: error and run time of a scene at a ladder of numerical settings."""

from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional

import typer

from ..config import load_config, parse_overrides
from ..errors import EXIT_PHYSICS
from .common import err, fail, guarded, out


def _fmt(value: float) -> str:
    return "" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.3g}"


def _order(name: str, value: float, flag: str) -> str:
    """'name 1.23', or with the reason it is meaningless (accuracy.order_flag)."""
    return f"{name} {value:.2f}" + (f" [not meaningful: {flag}]" if flag else "")


def _print_report(result: dict):
    from rich.table import Table

    from ..studies.accuracy import SCENE_ERRORS, order_value

    scene, analytic, start = result["scene"], result["analytic"], result["start"]
    if scene:
        table = Table(title=f"scene ladders from {start.source} over {start.interval:.4g} t0 "
                            "(relative error against the finest setting)")
        for col in ("ladder", "setting", "dt / step / cell", "run time [s]", "steps", *SCENE_ERRORS, "status"):
            table.add_column(col, justify="right")
        for r in scene["results"]:
            errors = ["ref" if r.level.reference and not r.errors else _fmt(r.errors.get(n)) for n in SCENE_ERRORS]
            table.add_row(r.level.ladder, r.level.setting, f"{order_value(r):.4g}", f"{r.wall_seconds:.2f}",
                          str(r.steps), *errors, r.status[:60])
        out.print(table)
        for ladder, orders in scene["orders"].items():
            flags = scene.get("order_flags", {}).get(ladder, {})
            shown = ", ".join(_order(k, v, flags.get(k, "")) for k, v in orders.items() if not math.isnan(v))
            out.print(f"observed order ({ladder}): {shown or 'n/a'}", highlight=False)
    if analytic:
        table = Table(title="analytic cases (relative error against the closed form)")
        for col in ("case", "parameter", "run time [s]", "errors"):
            table.add_column(col, justify="right")
        for r in analytic["rows"]:
            table.add_row(r.case, f"{r.parameter} = {r.value:.4g}", f"{r.wall_seconds:.3f}",
                          ", ".join(f"{k} {_fmt(v)}" for k, v in r.errors.items()))
        out.print(table)
        for case, orders in analytic["orders"].items():
            flags = analytic.get("order_flags", {}).get(case, {})
            out.print(f"observed order ({case}): " + ", ".join(_order(k, v, flags.get(k, ""))
                                                               for k, v in orders.items()), highlight=False)


def accuracy(
    config: Optional[Path] = typer.Argument(None, help="YAML scene config (optional with --slip-checkpoint)"),
    slip_checkpoint: Optional[Path] = typer.Option(
        None, "--slip-checkpoint", help="start every level from this checkpoint of `gouge run` (e.g. "
                                        "runs/NAME/checkpoints/slip_001.h5) instead of the scene's first slip"),
    quick: bool = typer.Option(False, "--quick", help="3 levels per ladder and short analytic cases"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="output directory (default runs/accuracy/<name>)"),
    interval: Optional[float] = typer.Option(None, "--interval", help="compared interval [t0] (default: lead "
                                                                      "to the slip + 1.5 slip durations)"),
    samples: int = typer.Option(400, "--samples", help="samples over the interval"),
    set_: List[str] = typer.Option([], "--set", help="override key=value of the scene"),
    analytic: bool = typer.Option(True, "--analytic/--no-analytic", help="also the analytic cases"),
    fluid: bool = typer.Option(True, "--fluid/--no-fluid", help="also the fluid ladders (a dry scene gets "
                                                                "kappa_c = 1e-5 for them)"),
    ladders: Optional[str] = typer.Option(
        None, "--ladders", help="only these scene ladders, comma-separated: dt_safety, grid, filter_width, "
                                "fluid.step, fluid.solver (default: all)"),
    stick_scaling: Optional[str] = typer.Option(
        None, "--stick-scaling", help="instead: the stick-scaling ladder over these lambdas, e.g. 1,4,16,64,256 "
                                      "(slip statistics and cost against lambda; gouge_cli.studies.scaling_ladder)"),
    seeds: int = typer.Option(3, "--seeds", min=2, help="stick-scaling ladder: seeds (config seed, +1, ...)"),
    transient: float = typer.Option(0.2, "--transient", min=0.0, max=0.9,
                                    help="stick-scaling ladder: fraction of the loading ignored as transient"),
    keep: bool = typer.Option(False, "--keep", help="stick-scaling ladder: keep the runs already in the output "
                                                    "directory (same scene) and run only the missing ones"),
):
    """Errors and run times of a scene at ladders of dt_safety, fluid grid spacing (at a fixed filter width), filter width, fluid step and solver, and of analytic cases; observed orders.

    Every level starts from the same pre-slip state and runs the same short interval (the DEM
    is chaotic: longer intervals measure the chaotic spread, not the discretisation error).
    Writes accuracy.csv and accuracy.png (work-precision: error vs run time)."""
    from ..studies.accuracy import run_accuracy
    from ..errors import PhysicsError

    if config is None and slip_checkpoint is None:
        fail("give a CONFIG, a --slip-checkpoint, or both")
    set_ = parse_overrides(set_)        # {dotted key: value}, parsed here once
    if stick_scaling is not None:           # stick scaling: its own ladder
        return _stick_ladder(config, set_, stick_scaling, seeds, transient, out_dir, keep)
    try:
        cfg = load_config(config, set_) if config is not None else None
        if cfg is None and set_:
            from ..io.checkpoint import read_checkpoint

            cfg = read_checkpoint(slip_checkpoint, set_).config
        name = cfg.name if cfg is not None else Path(slip_checkpoint).stem
        target = out_dir or Path("runs") / "accuracy" / name
        result = run_accuracy(cfg, target, checkpoint=slip_checkpoint, quick=quick, interval=interval,
                              samples=samples, analytic=analytic, fluid=fluid,
                              ladders=_ladder_names(ladders),
                              on_level=lambda r: err.print(f"{r.level.ladder} {r.level.setting}: {r.status[:80]} "
                                                           f"({r.wall_seconds:.2f} s)", highlight=False))
    except PhysicsError as e:
        fail(f"physics failure while preparing the scene: {e}", EXIT_PHYSICS)
    _print_report(result)
    out.print(f"results: {target / 'accuracy.csv'}, {target / 'accuracy.png'}", highlight=False)


def _ladder_names(text: Optional[str]) -> Optional[tuple]:
    """The --ladders list, checked against the scene ladders' names (exit 2 naming an unknown one)."""
    from ..studies.accuracy import LADDERS

    if text is None:
        return None
    names = tuple(part.strip() for part in text.split(",") if part.strip())
    unknown = [n for n in names if n not in LADDERS]
    if unknown or not names:
        fail(f"--ladders: unknown ladder {', '.join(map(repr, unknown)) or '(none given)'}; "
             f"choose from {', '.join(LADDERS)}")
    return names


def register(app: typer.Typer):
    app.command("accuracy")(guarded(accuracy))


def _stick_ladder(config, set_, lambdas, seeds, transient, out_dir, keep=False):
    """`gouge accuracy CONFIG --stick-scaling 1,4,16 --seeds 3`: run, print the table, write files."""
    from ..studies.scaling_ladder import QUANTITIES, run_ladder

    if config is None:
        fail("--stick-scaling needs a CONFIG (a scene that stick-slips repeatedly)")
    try:
        values = [float(v) for v in lambdas.split(",") if v.strip()]
    except ValueError:
        fail(f"--stick-scaling: {lambdas!r} is not a comma-separated list of numbers")
    if not values or min(values) < 1.0:
        fail(f"--stick-scaling: every lambda must be >= 1 (got {lambdas})")
    cfg = load_config(config, set_)           # ConfigError / PhysicsError: exit codes through guarded
    target = out_dir or Path("runs") / "accuracy" / f"{cfg.name}_stick_scaling"
    result = run_ladder(cfg, values, seeds, target, transient, progress=lambda r: err.print(
        f"lambda {r['lam']:g} seed {r['seed']}: {len(r['slips'])} slips, {r['steps']} steps, {r['wall']:.1f} s",
        highlight=False), keep=keep)
    from rich.table import Table

    table = Table(title=f"stick-scaling ladder ({seeds} seeds; differences from lambda = 1: mean ± 95 % CI "
                        "[lambda = 1 seed-to-seed spread])")
    for col in ("lambda", "slips/seed", "grain-steps/cycle", "speed-up", "wall s/cycle", "I max", *QUANTITIES, "ok"):
        table.add_column(col, justify="right")
    for r in result["rows"]:
        table.add_row(f"{r['lambda']:g}", f"{r['slips_per_seed']:.1f}", f"{r['grain_steps_per_cycle']:.3g}",
                      f"{r['speedup']:.2f}", f"{r['wall_s_per_cycle']:.3g}", _fmt(r["i_max"]),
                      *[f"{_fmt(r[q + '_diff'])} ± {_fmt(r[q + '_ci95'])} [{_fmt(r[q + '_spread'])}]"
                        for q in QUANTITIES], "yes" if r["within_spread"] else "no")
    out.print(table)
    out.print(f"default (largest lambda with every difference within the spread): {result['default']:g}; "
              f"files: {target / 'scaling_ladder.csv'}, {target / 'scaling_ladder.png'}", highlight=False)
