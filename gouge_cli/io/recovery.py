"""Crash recovery of a run file (a resume's part; module doc of :mod:`gouge_cli.io.runfile`): the
series tail a checkpoint records (:class:`SeriesTail`), the mending of a chunk a killed flush left
under its old Fletcher-32 (:func:`torn_series_tail`, :func:`mend_series_tail`), and the rebuild of
a file holding an object that cannot be opened (:func:`rebuild_openable`)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from .integrity import STRUCTURE_ERRORS
from .outputs import remove_temps, require_space, temporary
from .runfile import SERIES_CHUNK


def rows_digest(values: np.ndarray) -> str:
    """SHA-256 (hex) of float64 rows as little-endian bytes."""
    return hashlib.sha256(np.ascontiguousarray(values, dtype="<f8").tobytes()).hexdigest()


@dataclass(frozen=True)
class SeriesTail:
    """What a checkpoint records of the series it lines up with: `rows` flushed rows, and per
    column the SHA-256 of its rows in the last, partly filled chunk ([start, rows), the only rows
    before the checkpoint that a later flush rewrites; empty when rows fill whole chunks)."""

    rows: int
    digests: dict = field(default_factory=dict)

    @property
    def start(self) -> int:
        return self.rows - self.rows % SERIES_CHUNK


def torn_series_tail(path: Path, tail: SeriesTail | None) -> dict[str, tuple[bytes, np.ndarray]]:
    """The series columns of run file `path` (read only) whose chunk holding rows
    [tail.start, tail.rows) fails its Fletcher-32 while those rows' bytes match the checkpoint's
    digest: a flush after the checkpoint stopped inside its write (module doc). name -> (the
    chunk's bytes without the checksum, the tail's rows). A column whose rows do not match, or
    whose chunk cannot be read raw, is not in it (it is damaged, and refused by the resume)."""
    if tail is None or not tail.digests:
        return {}
    start, count = tail.start, tail.rows - tail.start
    torn = {}
    with h5py.File(path, "r") as h5:
        for name, digest in tail.digests.items():
            ds = h5["series"].get(name)
            if ds is None or ds.shape[0] < tail.rows or ds.dtype != np.dtype("<f8") or ds.chunks != (SERIES_CHUNK,):
                continue
            try:
                ds[start:tail.rows]
                continue                            # sound
            except OSError:
                pass
            try:
                mask, raw = ds.id.read_direct_chunk((start,))
            except (OSError, RuntimeError, ValueError):
                continue
            if mask != 0 or len(raw) != SERIES_CHUNK * 8 + 4:   # (the data and its Fletcher-32)
                continue
            values = np.frombuffer(raw, "<f8", count=count)
            if rows_digest(values) == digest:
                torn[name] = (raw[:-4], values.copy())
    return torn


def mend_series_tail(path: Path, tail: SeriesTail | None) -> list[str]:
    """Mend the torn_series_tail columns of run file `path` (opened for writing only if there is
    one): the chunk's bytes written back unfiltered, then the tail's rows once more through HDF5,
    which checksums them anew. Returns the mended columns' names."""
    torn = torn_series_tail(path, tail)
    if torn:
        with h5py.File(path, "r+", rdcc_nbytes=0) as h5:
            for name, (data, _) in torn.items():        # Fletcher-32 marked as not applied
                h5["series"][name].id.write_direct_chunk((tail.start,), data, filter_mask=1)
        with h5py.File(path, "r+", rdcc_nbytes=0) as h5:    # (a new handle: the old one keeps the former mask)
            for name, (_, values) in torn.items():
                h5["series"][name][tail.start:tail.rows] = values
    return sorted(torn)


def _copy_attributes(src, dst) -> None:
    for name in src.attrs:         # (each with its stored type, so the seals still match)
        dst.attrs.create(name, src.attrs[name], dtype=src.attrs.get_id(name).dtype)


def rebuild_openable(path: Path, next_step: str) -> None:
    """Replace run file `path` by a copy of every object in it that can be opened (HDF5's object
    copy: attributes, seals, chunks and checksums as they were), written to a temporary file
    renamed onto `path` when complete. For a file holding, after its checkpoint, an object that
    cannot be opened (a kill inside an HDF5 flush can leave a link to an object header past the end
    the file records): HDF5 cannot delete such a link, so truncate_after could not drop it; it
    trims the copy instead. Only after the resume's check (nothing it keeps fails to open)."""
    path = Path(path)
    remove_temps(path)
    require_space(path.parent, path.stat().st_size, f"rebuilding {path}", next_step)
    with temporary(path, next_step) as tmp:
        with h5py.File(path, "r") as src, h5py.File(tmp, "w", rdcc_nbytes=0) as dst:
            _copy_attributes(src, dst)
            for group in src:                      # (series, snapshots, slips: groups of objects)
                out = dst.create_group(group)
                _copy_attributes(src[group], out)
                for name in src[group]:
                    try:
                        src.copy(src[group][name], out)
                    except STRUCTURE_ERRORS:        # (what the resume drops)
                        continue
