"""`gouge verify`: thin wrapper over gouge_cli.io.verify (registered from cli/main.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from .common import guarded, out
from ..errors import EXIT_BAD_INPUT


def register(app: typer.Typer) -> None:
    """Add the `verify` command to ``app``."""

    @app.command()
    @guarded
    def verify(
        run_dir: Optional[Path] = typer.Argument(None, help="run directory (default: the latest under runs/)"),
        as_json: bool = typer.Option(False, "--json", help="machine-readable report"),
    ):
        """Read every file of a run (run.h5, checkpoints, fork branches) and check its checksums;
        report what is sound, what is damaged and what recomputes it. Exit 2 if anything is damaged."""
        import json

        from ..io.rundir import check_run_dir, latest_run
        from ..io.verify import describe_report, verify_run

        report = verify_run(check_run_dir(run_dir) if run_dir else latest_run())
        if as_json:
            out.print(json.dumps(report, indent=2), highlight=False, markup=False)
        else:
            out.print(describe_report(report), highlight=False, markup=False)
        if not report["sound"]:
            raise typer.Exit(EXIT_BAD_INPUT)
