"""What every `gouge` command shares: the consoles, `fail` (message + exit code) and `guarded`,
the one place where exceptions become exit codes (via gouge_cli.errors.describe, which owns the
codes: 0 done, 2 bad input, 3 physics failure or full disk, 130 interrupted)."""

from __future__ import annotations

import functools
import os
import sys

import typer
from rich.console import Console
from rich.markup import escape

from ..errors import EXIT_BAD_INPUT, ConfigError, InputError, PhysicsFailure, bounded, describe


# a terminal's width, or $COLUMNS when set (a pipe, the docs' tutorials); else 200 columns for a pipe
_WIDE = None if sys.stdout.isatty() or os.environ.get("COLUMNS", "").isdigit() else 200



err = Console(stderr=True, soft_wrap=True, width=_WIDE)



out = Console(soft_wrap=True, width=_WIDE)



def fail(message: str, code: int = EXIT_BAD_INPUT):
    err.print(f"[bold red]error:[/] {escape(bounded(message))}", highlight=False)
    raise typer.Exit(code)



def interactive() -> bool:
    """Whether a person at a terminal can answer a question (stdin is a terminal)."""
    return sys.stdin.isatty()


def confirm_long(yes: bool):
    """``confirm(note)`` for a long run (gouge_cli.workflows.run.run_scene): True with --yes; on a
    terminal, the user's answer; off a terminal, a ConfigError asking for --yes (exit 2)."""

    def confirm(note: str) -> bool:
        if yes:
            return True
        if interactive():
            return typer.confirm(f"{note.removeprefix('note: ')}. Start it?", default=False, err=True)
        raise ConfigError(f"not started (nothing was written): {note.removeprefix('note: ')}; pass --yes to "
                          "start it where no terminal can confirm it")

    return confirm


def guarded(command):
    """Run a command with the exit-code mapping of gouge_cli.errors.describe: bad input 2,
    physics failure or a full disk 3, Ctrl-C 130, each with a short message naming the key or path."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except (InputError, PhysicsFailure, OSError, RuntimeError, KeyboardInterrupt) as e:
            where = next((kwargs[k] for k in ("run_dir", "out_dir", "config", "run_dirs") if kwargs.get(k)), None)
            described = describe(e, str(where) if where is not None else None)
            if described is None:
                raise
            fail(*described)

    return wrapper
