"""`gouge dilatancy`: velocity steps in steady sliding (gouge_cli.studies.dilatancy)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from .common import guarded


def register(app: typer.Typer) -> None:
    """Add the `dilatancy` command to ``app``."""

    @app.command()
    @guarded
    def dilatancy(
        config: Path = typer.Argument(..., help="YAML scene config (its packing, walls and loading velocity V_1)"),
        sigma: List[float] = typer.Option([], "--sigma", help="normal stress [E]; repeatable (default: the config's)"),
        seeds: str = typer.Option("1-4", "--seeds", help="seeds, e.g. 1-4 or 1,3,5"),
        ratio: List[float] = typer.Option([10.0, 100.0], "--ratio", help="velocity step V_2 / V_1; repeatable"),
        perm: float = typer.Option(1e-9, "--perm", help="kappa_c [d^2] of the undrained steps (0: drained only)"),
        stiff: float = typer.Option(1e-2, "--stiff", help="spring constant [E/d] for steady sliding"),
        slip: float = typer.Option(40.0, "--slip", help="slip of each segment [d]; its second half is averaged"),
        run_in: float = typer.Option(25.0, "--run-in", help="slip at V_1 before the steps [d]"),
        workers: int = typer.Option(1, "--workers", help="(seed, sigma) points run at once"),
        out_dir: Path = typer.Option(Path("dilatancy"), "--out", help="records folder (dilatancy_runs.json: kept "
                                     "points are reused)"),
        report: Optional[Path] = typer.Option(None, "--report", help="folder for segments.csv, summary.md, dilatancy.png "
                                    "(default: --out)"),
        set_: List[str] = typer.Option([], "--set", help="config override"),
        tables: bool = typer.Option(False, "--tables", help="run nothing: the tables and figure from the kept points"),
    ):
        """Dilatancy coefficient eps = dphi/dlnV from velocity steps, and the undrained strengthening it predicts."""
        from ..config import load_config
        from ..studies.dilatancy import run_study, write_outputs
        from ..workflows.study import parse_slips
        from .common import fail, out

        try:
            seed_list = parse_slips(seeds)
        except ValueError:
            fail(f"--seeds {seeds!r}: give a range like 1-4 or a list like 1,3,5")
        if any(r <= 1.0 for r in ratio):
            fail(f"--ratio {ratio}: every step must be above 1 (V_2 > V_1)")
        cfg = load_config(config, set_)
        sigmas = sigma or [cfg.loading.normal_stress]
        say = lambda m: out.print(m, highlight=False)  # noqa: E731
        runs = run_study(cfg, seed_list, sigmas, out_dir, workers=workers, on_progress=say, tables_only=tables,
                         ratios=tuple(ratio),
                         perm=perm if perm > 0 else None, stiff=stiff, slip=slip, run_in=run_in)
        report = report or out_dir
        for path in write_outputs(runs, report):
            say(f"wrote {path}")
        say((report / "summary.md").read_text())
