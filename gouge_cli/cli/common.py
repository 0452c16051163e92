"""What every `gouge` command shares: the consoles, `fail` (message + exit code) and `guarded`,
the one place where exceptions become exit codes (via gouge_cli.errors.describe, which owns the
codes: 0 done, 2 bad input, 3 physics failure or full disk, 130 interrupted)."""

from __future__ import annotations

import contextlib
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



def main_event(value: str) -> str:
    """The ``--main`` options' callback: the value through MainEvent.check (analysis.pairs, the one
    check), exit 2 naming the option otherwise."""
    from ..analysis.pairs import MainEvent

    try:
        return MainEvent.check(value)
    except ConfigError as exc:
        fail(str(exc))


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


def _with_next_step(exc, name: str, kwargs: dict):
    """A full disk met by command `name` without its own advice: the advice that continues it
    (`gouge resume RUN` for a run; for the other commands, the same command again)."""
    from ..errors import NoSpaceError, hdf5_os_error
    from ..io.outputs import is_no_space

    if getattr(exc, "next_step", None) or not is_no_space(exc):
        return exc
    name = {"figures": "plot"}.get(name, name)          # `gouge plot` runs api.figures guarded
    cause = exc if isinstance(exc, OSError) else hdf5_os_error(exc) or exc
    path = getattr(cause, "filename", None) or str(kwargs.get("run_dir") or kwargs.get("out_dir") or ".")
    run = kwargs.get("out_dir") if name == "run" else kwargs.get("run_dir")
    if name in ("run", "resume"):
        step = f"`gouge resume{f' {run}' if run is not None else ''}` (the last good checkpoint is kept)"
    else:
        target = f" {kwargs['run_dir']}" if kwargs.get("run_dir") and not isinstance(kwargs["run_dir"], list) else ""
        step = (f"run `gouge {name.replace('_', '-')}{target}` again with the same options (what it wrote is "
                "kept or written anew)")
    return NoSpaceError(path, step)


@contextlib.contextmanager
def stop_signals():
    """SIGTERM and SIGHUP act as Ctrl-C while a command runs (KeyboardInterrupt: the run stops
    cleanly, with a checkpoint, status 'interrupted' and no temporary file; inside the step loop
    the first one is deferred to the end of the chunk, driver.phases.deferred_interrupt)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        raise KeyboardInterrupt(f"stopped by {signal.Signals(signum).name}")

    sigs = [getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)]
    previous = {s: signal.signal(s, stop) for s in sigs}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


def guarded(command):
    """Run a command with the exit-code mapping of gouge_cli.errors.describe: bad input 2,
    physics failure or a full disk 3, Ctrl-C, SIGTERM or SIGHUP 130, each with a short message
    naming the key or path."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            with stop_signals():
                return command(*args, **kwargs)
        except (InputError, PhysicsFailure, OSError, RuntimeError, KeyboardInterrupt) as e:
            where = next((kwargs[k] for k in ("run_dir", "out_dir", "config", "run_dirs") if kwargs.get(k)), None)
            if isinstance(e, (OSError, RuntimeError)):
                e = _with_next_step(e, command.__name__, kwargs)
            described = describe(e, str(where) if where is not None else None)
            if described is None:
                raise
            fail(*described)

    return wrapper


def restart_lines(summary, run_dir) -> list[str]:
    """`gouge restart`'s one-screen result: one line per branch (status, onset, strength, drop,
    peak velocity of its first slip), two per pair (its type, S_u - S_d, the two onsets and what
    made it complex; when S_d and S_u were reached), and where the whole record is. Times in t0
    since loading began; ``summary``: workflows.fork.ForkSummary."""
    from ..io.layout import RunLayout

    lines = [f"slip {summary.slip} forked from t = {summary.start_time:,.1f} t0 (since loading began)"]
    for name, b in summary.branches.items():
        f = b.first_slip
        slip = (f"onset {f.onset_time:,.1f} t0, S {f.static_strength:.4f}, drop {f.stress_drop:.4f} tau/sigma, "
                f"peak {f.peak_velocity_over_Vs:.3g} V_s" if f else "no slip in its window")
        lines.append(f"  {name:<12} {b.status:<18} {slip}")
    for row in (summary.pair or {}).get("pairs", []):
        diff = row.get("strength_difference")
        said = f"Type {row['type']}" if row["base_type"] in ("I", "II") else row["type"]
        onsets = (f"onsets {row['drained_onset']:,.1f} / {row['undrained_onset']:,.1f} t0"
                  if row.get("undrained_onset") is not None else "")
        complex_ = f"; complex: {row['criteria']}" if row.get("criteria") else ""
        lines.append(f"  pair drained vs {row['branch']}: {said}"
                     + (f" (S_u - S_d = {diff:+.4f} tau/sigma; {onsets})"
                        if isinstance(diff, float) and diff == diff else "") + complex_)
        when_d, when_u = row.get("drained_strength_time"), row.get("undrained_strength_time")
        if isinstance(when_d, float) and isinstance(when_u, float) and when_d == when_d and when_u == when_u:
            lines.append(f"    S_d reached at t = {when_d:,.1f}, S_u at {when_u:,.1f} t0 (the largest tau/sigma "
                         "before each onset)")
    fork = RunLayout(run_dir).fork(summary.slip)
    if summary.pair:
        lines.append(f"record: {fork.pair_file} (the whole of it: --json; `gouge plot {run_dir} --slip "
                     f"{summary.slip}` draws it)")
    return lines
