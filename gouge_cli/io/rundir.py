"""Run directories: what makes a directory a gouge run, and the lock that keeps one process at a time.

A run directory holds ``.gouge.lock`` (created first, before anything else is written),
``config.yaml``, ``run.h5``, ``checkpoints/`` and later ``forks/``, ``analysis/``, ``figures/``.
A process that writes into it (run, resume, restart) holds an exclusive ``fcntl.flock`` on
``.gouge.lock`` for as long as it runs, with its PID written in the file. The kernel drops the
lock when the process dies (even by kill -9), so a lock file whose lock is free is stale and is
simply taken over. ``gouge run --out DIR`` uses DIR if it is missing or empty, or if it is a gouge
run (``--force`` then removes only the entries of OWNED, never anything else); any other
directory, a regular file, or a run whose lock is held is refused. A campaign point directory's
``point.yaml`` and ``ledger/`` (CAMPAIGN_ENTRIES) count as empty, and so does a start killed
before its first checkpoint (:func:`killed_start`: nothing in it to resume or keep), which a new
run replaces without ``--force``.
"""

from __future__ import annotations

import errno
import fcntl
import os
import shlex
import shutil
from pathlib import Path

import h5py

from ..config import format_override
from ..errors import RunDirError
from .layout import OWNED, RUN_FILE, RunLayout, perm_text, runs_under

LOCK_NAME = ".gouge.lock"
CONTINUE = "; continued by: "       # in a lock file: the command that continues the holder's work
# a campaign point directory (gouge campaign) holds its state point and ledger beside the run:
# they make no directory foreign, count as no run, and are never removed by --force
CAMPAIGN_ENTRIES = ("point.yaml", "ledger")


class RunLock:
    """Exclusive lock of a run directory (module doc). Use as a context manager or release()."""

    def __init__(self, run_dir: Path, what: str = "gouge", then: str | None = None):
        """``then``: the command that continues the holder's work once it is stopped (written
        into the lock file and named to a second process; default `gouge resume RUN`)."""
        self.run_dir = Path(run_dir)
        path = self.run_dir / LOCK_NAME
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 1000, 0).decode(errors="replace").strip() or "unknown process"
            os.close(fd)
            holder, _, then = holder.partition(CONTINUE)
            then = then.strip() or shlex.join(["gouge", "resume", str(self.run_dir)])
            raise RunDirError(f"{self.run_dir} is in use by a gouge process in progress ({holder}); wait for it "
                              f"to finish, or stop it (Ctrl-C) and run `{then}` to continue its work") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"PID {os.getpid()}, {what}{CONTINUE + then if then else ''}\n".encode(), 0)
        self.fd = fd

    def release(self):
        if self.fd is not None:
            os.close(self.fd)       # drops the flock; the file stays as the mark of a gouge run
            self.fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def pid_alive(pid: int) -> bool:
    """Whether a process with this PID runs on this host (a stale lock or temp file's writer); a
    zombie (killed, not yet reaped by an init that reaps late) is not running."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def holder(run_dir: Path) -> str | None:
    """Who holds the lock of run_dir ('PID n, command'), or None when it is free or absent."""
    path = Path(run_dir) / LOCK_NAME
    if not path.is_file():
        return None
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return None
    except BlockingIOError:
        return os.pread(fd, 200, 0).decode(errors="replace").strip() or "unknown process"
    finally:
        os.close(fd)


def refuse_if_in_progress(run_dir: Path, command: str):
    """RunDirError if a gouge process is writing into run_dir."""
    who = holder(run_dir)
    if who is not None:
        raise RunDirError(f"{run_dir} is a run in progress ({who}); `gouge {command}` works on it once it has "
                          "finished or stopped")


def open_run_file(path: Path, mode: str = "r") -> h5py.File:
    """h5py.File, with the path named in the OSError of a damaged, truncated or locked file."""
    try:
        return h5py.File(path, mode)
    except OSError as err:
        if err.filename:
            raise
        raise OSError(err.errno, str(err).splitlines()[0] if str(err) else "cannot open", str(path)) from None


def is_gouge_run(run_dir: Path) -> bool:
    """True for a directory a gouge run made: it has the lock file, or a run.h5 with gouge's attributes."""
    run_dir = Path(run_dir)
    if (run_dir / LOCK_NAME).is_file():
        return True
    try:
        with h5py.File(RunLayout(run_dir).run_file, "r") as h5:
            return "config" in h5.attrs and "version" in h5.attrs
    except (OSError, KeyError):
        return False


def killed_start(run_dir: Path) -> bool:
    """True for a run killed before its first checkpoint: its lock is free, it has no
    checkpoints, forks or analysis, and its run.h5 is missing, unreadable or still 'running'."""
    run_dir = Path(run_dir)
    layout = RunLayout(run_dir)
    if holder(run_dir) is not None or layout.latest.exists() or \
            layout.slip_checkpoints() or layout.forks.exists() or layout.analysis.exists():
        return False
    if not layout.run_file.exists():
        return True
    try:
        with h5py.File(layout.run_file, "r") as h5:
            return str(h5.attrs.get("status", "running")) == "running"
    except OSError:         # cut short while it was created
        return True


def prepare_run_dir(out_dir: Path, force: bool = False) -> RunLock:
    """Make out_dir ready for a new run and return its lock (module doc for the rules)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise RunDirError(f"--out {out_dir} is a file, not a directory; choose a directory for the run")
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = sorted(p.name for p in out_dir.iterdir() if p.name not in CAMPAIGN_ENTRIES)
    if entries and not is_gouge_run(out_dir):
        shown = ", ".join(entries[:5]) + (", ..." if len(entries) > 5 else "")
        raise RunDirError(f"{out_dir} is not empty and is not a gouge run directory (it holds {shown}); "
                          "nothing was changed: choose a new or empty --out")
    if [e for e in entries if e != LOCK_NAME] and not force and not killed_start(out_dir):   # refused before the lock
        if (who := holder(out_dir)) is not None:
            raise RunDirError(f"{out_dir} is in use by a gouge process in progress ({who}); nothing was changed")
        raise RunDirError(f"{out_dir} already holds a run; choose another --out, another name (--set name=...), "
                          "or pass --force to replace it")
    lock = RunLock(out_dir, "gouge run")
    busy = [who for branch in RunLayout(out_dir).branch_dirs() if (who := holder(branch)) is not None]
    if busy:
        lock.release()
        raise RunDirError(f"{out_dir} has a fork in progress ({busy[0]}); nothing was changed: wait for it or "
                          "stop it first")
    try:
        for name in OWNED:      # they belonged to the run being replaced
            target = out_dir / name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            elif target.exists() or target.is_symlink():
                target.unlink()
    except BaseException:
        lock.release()
        raise
    return lock


SPACE_MARGIN = 4_000_000     # bytes kept free beyond the next checkpoints
RESERVE_BYTES = 500_000      # of them, allocated past a run file's end for its close (io.runwriter.RunFile._room)


def ensure_space(run_dir: Path, need: float):
    """OSError(ENOSPC) naming run_dir when fewer than `need` + SPACE_MARGIN bytes are free on
    its file system: raised before a write, so the run stops cleanly (files closed, the last
    checkpoint intact) instead of HDF5 failing half-way through one."""
    free = shutil.disk_usage(run_dir).free
    if free + RESERVE_BYTES < need + SPACE_MARGIN:        # (the run file's reserve is part of the margin)
        raise OSError(errno.ENOSPC, f"No space left on device ({free / 1e6:.1f} MB free, the next checkpoints need "
                      f"about {(need + SPACE_MARGIN) / 1e6:.1f} MB)", str(run_dir))


def check_run_dir(run_dir: Path) -> Path:
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir} is not a gouge run directory (no such directory)")
    if not RunLayout(run_dir).run_file.is_file() and not (run_dir / LOCK_NAME).is_file():
        raise RunDirError(f"{run_dir} is not a gouge run directory (no {RUN_FILE} in it)")
    return run_dir


def latest_run(runs_root: Path = Path("runs")) -> Path:
    """The most recently modified run directory under runs_root."""
    candidates = runs_under(runs_root)
    if not candidates:
        raise RunDirError(f"no runs under {runs_root}/; run `gouge run CONFIG` first or name the run directory")
    return max(candidates, key=lambda p: RunLayout(p).run_file.stat().st_mtime)


def restart_command(run_dir: Path, slip: int, perms: list[float], overrides: dict | None = None,
                    duration: float | None = None) -> str:
    """The `gouge restart` command line that runs this fork (named in the messages of a stopped one);
    ``overrides``: {dotted key: value} (config.parse_overrides), written back as ``--set`` strings."""
    args = ["gouge", "restart", str(run_dir), "--slip", str(slip)]
    for perm in perms:
        args += ["--perm", perm_text(perm)]       # as its branch folder spells it (perm_<perm_text>)
    for key, value in (overrides or {}).items():
        args += ["--set", format_override(key, value)]
    if duration is not None:
        args += ["--duration", f"{duration:g}"]
    return shlex.join(args)
