"""Files a command writes beside or outside a run (an export, a movie): what ``--out`` may name,
the free space a sized write needs, and the temporary file that becomes the output only when
it is complete.

* :func:`check_out` refuses (InputError, exit 2) an ``--out`` that is a directory, a device or
  a FIFO, one of a run's own files (``run.h5``, ``config.yaml``, checkpoints, the lock, a
  fork's ``pair.json``), or an existing file of another kind than the command writes; an
  existing file of its own kind is replaced only with ``--force`` (or at the command's default
  path, which is its own).
* :func:`require_space` refuses a write of a known size when the file system lacks it plus
  SPACE_MARGIN (NoSpaceError, exit 3, naming how much to free and the command that continues).
* :func:`preallocate` gives an in-place HDF5 write its room on disk before it starts (the run
  file's writes and its reserve for the close, ``gouge analyze``'s tables in run.h5).
* :func:`temporary` yields a hidden temporary path in the destination folder; the caller writes
  it whole and it is renamed onto the output, or removed when anything fails (a full disk
  included), so no partial output and no temporary file is left, and an earlier output stays
  whole until the new one replaces it (a fork branch's run.h5 too, workflows.fork).
"""

from __future__ import annotations

import errno
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

from ..config import not_a_file
from ..errors import InputError, NoSpaceError
from .layout import CHECKPOINTS, CONFIG_FILE, LATEST, PAIR_FILE, RUN_FILE
from .rundir import LOCK_NAME

SPACE_MARGIN = 256_000          # bytes left free beyond a sized write
RUN_FILES = {RUN_FILE, CONFIG_FILE, LOCK_NAME, PAIR_FILE, LATEST, "point.yaml"}


def run_owned(path: Path) -> bool:
    """Whether `path` is one of a run's own files: run.h5, config.yaml, the lock, pair.json, or
    anything under a run's checkpoints/ (a run: a folder holding run.h5 or the lock)."""
    path = Path(path).absolute()
    if path.name in RUN_FILES or (path.name.startswith("slip_") and path.suffix == ".h5"):
        return True
    for parent in path.parents:
        if parent.name == CHECKPOINTS and ((parent.parent / RUN_FILE).exists()
                                             or (parent.parent / LOCK_NAME).exists()):
            return True
    return False


def check_out(path: Path | str, same_kind, what: str, force: bool, default: bool = False) -> Path:
    """``path`` if the command may write it (module doc), else InputError naming why.
    ``same_kind(path)``: whether an existing file is one this command wrote; ``what``: its
    description ('a VTKHDF export'); ``default``: the command's own default path."""
    path = Path(path)
    kind = not_a_file(path)
    if kind is not None:
        raise InputError(f"--out {path} is {kind}, not a file; name the file to write (nothing was written)")
    if not path.exists():
        if run_owned(path):
            raise InputError(f"--out {path} names a run's own file; choose a path outside the run's own files "
                             "(nothing was written)")
        if (parent := _existing_parent(path)) is not None and not parent.is_dir():
            raise InputError(f"--out {path}: {parent} is a file, not a directory (nothing was written)")
        return path
    if run_owned(path) or not same_kind(path):
        raise InputError(f"--out {path} exists and is not {what} this command wrote (it is kept; nothing was "
                         "written): choose another --out")
    if not (force or default):
        raise InputError(f"--out {path} exists ({what}); pass --force to replace it, or choose another --out "
                         "(nothing was written)")
    return path


def _existing_parent(path: Path) -> Path | None:
    for parent in Path(path).absolute().parents:
        if os.path.lexists(parent):
            return parent
    return None


def free_bytes(folder: Path) -> int:
    """Free bytes for this process on the file system of `folder` (or its nearest existing parent)."""
    folder = Path(folder)
    existing = folder if folder.exists() else _existing_parent(folder)
    return shutil.disk_usage(existing or Path.cwd()).free


def require_space(folder: Path, need: float, what: str, next_step: str | None = None) -> None:
    """NoSpaceError unless `need` + SPACE_MARGIN bytes are free where `folder` is (module doc)."""
    free = free_bytes(folder)
    if free < need + SPACE_MARGIN:
        raise NoSpaceError(str(folder), next_step, need=need + SPACE_MARGIN - free,
                           detail=f"{what} needs about {(need + SPACE_MARGIN) / 1e6:.1f} MB, "
                                  f"{free / 1e6:.1f} MB are free")


def preallocate(path: Path, nbytes: int, start: int | None = None) -> bool:
    """Allocate the disk blocks of bytes [start, start + nbytes) of the existing file `path`
    (start: its end), growing it if needed, before an HDF5 write: HDF5 writes past its own end
    (its end of allocation, below the file's size) into blocks it already holds, so that write
    cannot meet a full disk, whatever else writes to the disk (on a full disk HDF5 left a file
    unreadable or crashed the process); a close of a file opened after the allocation trims it
    to HDF5's end, other bytes past it are ignored by HDF5. ENOSPC (or EDQUOT) here, before
    anything is written, when the room is not there (the file keeps its size). False where the
    OS or the file system cannot allocate (no posix_fallocate, EOPNOTSUPP)."""
    if not hasattr(os, "posix_fallocate"):
        return False
    fd = os.open(path, os.O_RDWR)
    try:
        size = os.fstat(fd).st_size
        try:
            os.posix_fallocate(fd, size if start is None else int(start), int(nbytes))
        except OSError as exc:
            if os.fstat(fd).st_size > size:
                os.ftruncate(fd, size)
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                raise
            return False
    finally:
        os.close(fd)
    return True


def temp_for(path: Path) -> Path:
    """The temporary file of an output: hidden, in its folder, with its suffix (encoders choose by it)."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


@contextmanager
def temporary(path: Path, next_step: str | None = None):
    """Yield the temporary path of output `path` (module doc); on success it is renamed onto
    `path`. A full disk (ENOSPC, also inside an encoder) raises NoSpaceError naming `next_step`
    (None: the command's own advice, cli.common.guarded)."""
    path = Path(path)
    tmp = temp_for(path)
    try:
        yield tmp
        with open(tmp, "rb") as fh:         # on disk before it takes the name (a crash keeps either file)
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        _remove(tmp)
        if is_no_space(exc) or (isinstance(exc, (OSError, RuntimeError, BrokenPipeError))
                                and free_bytes(path.parent) < SPACE_MARGIN):
            raise NoSpaceError(str(path.parent), next_step) from None
        raise


def remove_temps(path: Path) -> None:
    """Remove the temporary files of output `path` (and their reserves) left by a killed writer;
    called only while `path`'s folder is locked, when no live writer holds one."""
    path = Path(path)
    for stale in path.parent.glob(f"*.{path.stem}.*.tmp{path.suffix}*"):
        _remove(stale)


def write_bytes(path: Path, data: bytes, next_step: str | None = None) -> None:
    """Write `data` to `path` through its temporary file (checked for space first, fsync'd)."""
    path = Path(path)
    require_space(path.parent, len(data), f"{path.name} ({len(data) / 1e6:.1f} MB)", next_step)
    with temporary(path, next_step) as tmp:
        write_file(tmp, data)


def write_file(path: Path, data) -> None:
    """Write the bytes `data` (any buffer) to the file `path` (created or truncated) and fsync it;
    a full disk is the OSError of this write."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)


def is_no_space(exc: BaseException) -> bool:
    """Whether `exc` (or what it wraps) is a full disk."""
    seen = 0
    while exc is not None and seen < 5:
        if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        if "No space left on device" in str(exc) or "errno = 28" in str(exc):
            return True
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return False


def _remove(path: Path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
