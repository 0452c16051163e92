"""Exit codes and the one mapping from exceptions to them (used by every `gouge` command).

    0   done
    2   bad input: a config key, a run directory, a slip number, a damaged, unreadable or
        read-only file; nothing is run or written (InputError and its subclasses, OSError
        other than a full disk)
    3   the run could not go on: physics failure (PhysicsFailure, names the parameter to
        change) or a full disk (ENOSPC, names the path); the last good checkpoint is kept
    4   done, but something was skipped because it is damaged (`gouge analyze`, `gouge study`: a
        fork whose branch cannot be read; listed, with a summary line printed last)
    130 interrupted (outputs flushed)

Messages are one line, at most MAX_MESSAGE characters per line and MAX_LINES lines.
"""

from __future__ import annotations

import errno
import os
import re

EXIT_OK, EXIT_BAD_INPUT, EXIT_PHYSICS, EXIT_SKIPPED, EXIT_INTERRUPTED = 0, 2, 3, 4, 130
MAX_MESSAGE = 400       # characters per line of a message
MAX_LINES = 25


class InputError(ValueError):
    """Anything the user can fix in what they gave (exit 2); the message names the key or path."""

    exit_code = EXIT_BAD_INPUT


class PhysicsFailure(RuntimeError):
    """The run went physically wrong (exit 3); the message names the cause and the fix."""

    exit_code = EXIT_PHYSICS


def clip(text: str, limit: int = MAX_MESSAGE) -> str:
    """`text` cut to `limit` characters (with a note of how much was cut)."""
    text = str(text)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit} more characters)"


def bounded(message: str) -> str:
    """At most MAX_LINES lines of at most MAX_MESSAGE characters each."""
    lines = str(message).splitlines() or [""]
    out = [clip(line) for line in lines[:MAX_LINES]]
    if len(lines) > MAX_LINES:
        out.append(f"... and {len(lines) - MAX_LINES} more lines")
    return "\n".join(out)


def _first_line(text: str) -> str:
    return (str(text).strip().splitlines() or [""])[0]


def describe_os_error(exc: OSError, where: str | None = None) -> tuple[str, int]:
    """(one-line message, exit code) for a failed file operation. `where`: the run directory
    or file the command was working on, named when the error itself carries no path."""
    path = exc.filename or where or "a file"
    code = exc.errno
    if code == errno.ENOSPC or "No space left on device" in str(exc):
        then = getattr(exc, "next_step", None) or "`gouge resume` (the last good checkpoint is kept)"
        need = getattr(exc, "need", None)
        free = f"free at least {max(need / 1e6, 0.1):.1f} MB there" if need else "free some space there"
        detail = f" ({exc.detail})" if getattr(exc, "detail", "") else ""
        return f"no space left on device while writing {path}{detail}; {free} and {then}", EXIT_PHYSICS
    if code in (errno.EACCES, errno.EPERM, errno.EROFS):
        return f"permission denied: {path} cannot be written or read (read-only directory or file?)", EXIT_BAD_INPUT
    if code == errno.EISDIR:
        return f"{path} is a directory, expected a file", EXIT_BAD_INPUT
    if code in (errno.ENOTDIR, errno.EEXIST):
        return f"{path}: {exc.strerror or _first_line(exc)} (a file is in the way)", EXIT_BAD_INPUT
    reason = exc.strerror or _first_line(exc)
    if exc.errno is None:       # h5py/HDF5: damaged, truncated or locked file
        return f"{path}: damaged, truncated or unreadable HDF5 data ({clip(reason, 200)})", EXIT_BAD_INPUT
    return f"{path}: {clip(reason, 200)}", EXIT_BAD_INPUT


def hdf5_os_error(exc: RuntimeError, where: str | None = None) -> OSError | None:
    """The OSError inside an HDF5 RuntimeError ("file write failed ... errno = 28 ..."), or None."""
    match = re.search(r"errno = (\d+)", str(exc))
    if not match:
        return None
    name = re.search(r"filename = '([^']*)'", str(exc))
    code = int(match.group(1))
    return OSError(code, os.strerror(code), name.group(1) if name else where)


def describe(exc: BaseException, where: str | None = None) -> tuple[str, int] | None:
    """(message, exit code) for an error the user can act on, or None for a bug (let it raise).
    `where`: the run directory or file the command was working on."""
    if isinstance(exc, KeyboardInterrupt):
        return str(exc) or "interrupted", EXIT_INTERRUPTED
    if isinstance(exc, PhysicsFailure):
        return f"physics failure: {exc}", exc.exit_code
    if isinstance(exc, InputError):
        return str(exc), exc.exit_code
    if isinstance(exc, RuntimeError):
        exc = hdf5_os_error(exc, where)
    if isinstance(exc, OSError):
        return describe_os_error(exc, where)
    return None


class NoSpaceError(OSError):
    """A full disk (ENOSPC) stopped a command; ``next_step`` says what continues the work once
    space is freed (named in the message instead of `gouge resume`)."""

    def __init__(self, path: str, next_step: str, need: float | None = None, detail: str = ""):
        super().__init__(errno.ENOSPC, os.strerror(errno.ENOSPC), path)
        self.next_step = next_step
        self.need = need            # bytes to free, when the write could be sized
        self.detail = detail        # e.g. "the export needs about 3.1 MB, 0.2 MB are free"

    def __reduce__(self):           # raised in a worker process (gouge study), re-raised in its parent
        return NoSpaceError, (self.filename, self.next_step, self.need, self.detail)


class PhysicsError(PhysicsFailure):
    """The physics went wrong (NaN, runaway overlap, unstable fluid step); names cause and fix."""

    def __init__(self, cause: str, fix: str, time: float | None = None):
        self.cause, self.fix, self.time = cause, fix, time
        at = f" at t = {time:.6g} t0" if time is not None else ""
        super().__init__(f"{cause}{at}. {fix}")


class AnalysisError(InputError):
    """A run cannot be analysed as asked; the message says why and what to do."""



class NotARunError(AnalysisError):
    """The path is not a gouge run directory (no readable run.h5 with series)."""



class RunStillRunningError(AnalysisError):
    """The run or fork file still has status 'running'."""



class BranchInterruptedError(AnalysisError):
    """A fork branch was interrupted before its end: its pair is not classified until it is run again."""


class NoSlipsError(AnalysisError):
    """The run has no slip events to analyse."""



class SlipNotFoundError(AnalysisError):
    """No slip with the requested number."""


class ConfigError(InputError):
    """A config that cannot be run; the message is meant for the user."""


class RunDirError(InputError):
    """The run directory cannot be used (exists with results, is not a run, or is in use)."""


class CheckpointError(InputError):
    """A checkpoint that cannot be used (missing, truncated, corrupt)."""


class ExecutorError(InputError):
    """A cluster cannot be started as asked (bad option, missing package); exit code 2."""


class SpecError(ConfigError):
    """The campaign file cannot be used; the message names the key and what is allowed."""


class CampaignConflict(InputError):
    """Existing results were made with other settings; the message names the points and keys."""


class StudyInterrupted(RuntimeError):
    """The loading run was interrupted (Ctrl-C): no branch is started; `gouge study` again resumes it."""


class MovieError(AnalysisError):
    """The fork cannot be made into a movie (missing branch, no snapshots)."""


class ExportError(AnalysisError):
    """The run cannot be exported as asked (no snapshots, no such fork)."""


class DamagedFileError(InputError):
    """A file whose data or attributes fail their checksum, or cannot be read (exit 2); the message
    names the file, the dataset or attribute and, for series, the rows. Nothing is computed from it."""
