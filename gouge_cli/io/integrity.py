"""Integrity of gouge's HDF5 files: per-chunk checksums, attribute seals, checked reads.

Every dataset of a run file is either written with HDF5's Fletcher-32 filter (a checksum per
chunk, checked by HDF5 on every read) or, when it is small or holds strings, has its bytes
covered by its seal. Every group and dataset carries a seal: the attribute ``attrs_sha256``, a
SHA-256 over its other attributes (names, types, shapes and values) and, for a dataset without
Fletcher-32, its data. A checkpoint is covered by one digest over all its datasets and
attributes (:func:`content_digest`). Readers go through :func:`check_seal` and :func:`read`,
which turn a mismatch, an unreadable attribute or a failed chunk checksum into
:class:`DamagedFileError` (exit 2) naming the file, the object and, for series, the rows.
"""

from __future__ import annotations

import hashlib

import h5py
import numpy as np

from ..errors import DamagedFileError

SEAL = "attrs_sha256"


def value_bytes(value) -> bytes:
    """Canonical bytes of an attribute value or of a dataset's data (type, shape and content)."""
    if isinstance(value, str):
        return b"str:" + value.encode("utf-8", "surrogatepass")
    if isinstance(value, bytes):
        return b"bytes:" + value
    arr = np.asarray(value)
    if arr.dtype.kind == "O":       # variable-length strings (h5py returns str or bytes items)
        items = [v.encode("utf-8", "surrogatepass") if isinstance(v, str) else bytes(v) for v in arr.ravel()]
        return f"O:{arr.shape}:".encode() + b"\0".join(h + b"\1" for h in items)
    return f"{arr.dtype.str}:{arr.shape}:".encode() + np.ascontiguousarray(arr).tobytes()


def _where(obj) -> str:
    return f"{obj.file.filename}:{obj.name}"


def object_digest(obj, with_data: bool | None = None) -> str:
    """SHA-256 (hex) over the attributes of `obj` but its seal, in name order; for a dataset
    without Fletcher-32 (or with_data=True) also over its data. DamagedFileError when an
    attribute or the data cannot be read."""
    h = hashlib.sha256()
    try:
        names = sorted(k for k in obj.attrs.keys() if k != SEAL)
    except (OSError, RuntimeError, KeyError, ValueError) as err:
        raise DamagedFileError(f"{_where(obj)}: its attributes cannot be read ({_short(err)})") from None
    for name in names:
        try:
            value = obj.attrs[name]
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as err:   # UnicodeDecodeError is a ValueError
            raise DamagedFileError(f"{_where(obj)}: attribute {name!r} cannot be read ({_short(err)})") from None
        h.update(name.encode("utf-8", "surrogatepass") + b"=")
        h.update(value_bytes(value))
        h.update(b";")
    if isinstance(obj, h5py.Dataset) and (with_data or (with_data is None and not obj.fletcher32)):
        h.update(b"data=" + value_bytes(read(obj)))
    return h.hexdigest()


def attr_value(attrs, key, default=None):
    """Attribute `key` of `attrs` as a Python value (bytes decoded, numpy scalars unwrapped), or `default`."""
    if key not in attrs:
        return default
    value = attrs[key]
    if isinstance(value, bytes):
        return value.decode()
    return value.item() if hasattr(value, "item") else value


def seal(obj) -> None:
    """Store the seal of `obj` (call after its last attribute or, small datasets, its data is written)."""
    obj.attrs[SEAL] = object_digest(obj)


def seal_tree(group) -> None:
    """Seal `group` and every group and dataset below it."""
    seal(group)
    group.visititems(lambda _, obj: seal(obj))


def stored_seal(obj) -> str | None:
    """The seal `obj` carries, None if it has none (written before seals existed)."""
    try:
        if SEAL not in obj.attrs:
            return None
        value = obj.attrs[SEAL]
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as err:
        raise DamagedFileError(f"{_where(obj)}: its seal cannot be read ({_short(err)})") from None
    return value.decode() if isinstance(value, bytes) else str(value)


def check_seal(obj, required: bool = False) -> None:
    """DamagedFileError if the seal of `obj` does not match its attributes (and small data).
    An object without a seal passes unless `required` (a sealed file's objects all have one)."""
    stored = stored_seal(obj)
    if stored is None:
        if required:
            raise DamagedFileError(f"{_where(obj)}: its checksum attribute {SEAL!r} is missing")
        return
    if object_digest(obj) != stored:
        raise DamagedFileError(f"{_where(obj)}: its attributes{'' if obj_is_fletcher(obj) else ' or data'} do not "
                               "match their checksum (damaged file)")


STRUCTURE_ERRORS = (OSError, RuntimeError, KeyError)     # what h5py raises on damaged metadata


def structure_error(h5, err: BaseException) -> DamagedFileError:
    """DamagedFileError for a file whose HDF5 metadata (groups, links, heaps) cannot be walked."""
    return DamagedFileError(f"{h5.filename}: its HDF5 structure is damaged ({_short(err)})")


def obj_is_fletcher(obj) -> bool:
    return isinstance(obj, h5py.Dataset) and bool(obj.fletcher32)


def _short(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return (text[0] if text else type(err).__name__)[:160]


def damaged_rows(ds, start: int = 0, stop: int | None = None) -> list[tuple[int, int]]:
    """[(first, last)] rows of a 1D chunked dataset within start:stop whose chunk fails to read."""
    stop = ds.shape[0] if stop is None else stop
    size = ds.chunks[0] if ds.chunks else max(stop - start, 1)
    bad = []
    for a in range((start // size) * size, stop, size):
        b = min(a + size, ds.shape[0])
        try:
            ds[a:b]
        except OSError:
            lo, hi = max(a, start), min(b, stop) - 1
            if bad and bad[-1][1] == lo - 1:
                bad[-1] = (bad[-1][0], hi)
            else:
                bad.append((lo, hi))
    return bad


def read(ds, selection=Ellipsis) -> np.ndarray:
    """ds[selection]; a chunk failing its checksum (or any read error) is DamagedFileError naming
    the dataset and, for a 1D dataset, the damaged rows."""
    try:
        return ds[selection]
    except OSError as err:
        where = _where(ds)
        if ds.ndim == 1 and ds.chunks:
            sel = selection if isinstance(selection, slice) else slice(None)
            rows = damaged_rows(ds, *sel.indices(ds.shape[0])[:2])
            if rows:
                listed = ", ".join(f"{a}-{b}" if a != b else f"{a}" for a, b in rows[:5])
                raise DamagedFileError(f"{where}: rows {listed} (of {ds.shape[0]}) fail their checksum "
                                       "(damaged file)") from None
        raise DamagedFileError(f"{where}: cannot be read, damaged data ({_short(err)})") from None


def walk_objects(h5) -> tuple[dict, dict]:
    """({path: object}, {path: error}) of an open file's root and every group and dataset below it:
    an object that cannot be opened (damaged metadata, such as a link to an object header written
    past the end the file records when a kill cut an HDF5 flush short) is in the second, and what
    is below it is not walked."""
    objects, failures = {"/": h5}, {}

    def walk(group, prefix: str):
        try:
            names = list(group.keys())
        except STRUCTURE_ERRORS as err:
            failures[prefix.rstrip("/") or "/"] = err
            return
        for name in names:
            path = prefix + name
            try:
                obj = group[name]
            except STRUCTURE_ERRORS + (ValueError,) as err:
                failures[path] = err
                continue
            objects[path] = obj
            if isinstance(obj, h5py.Group):
                walk(obj, path + "/")

    walk(h5, "/")
    return objects, failures


def all_objects(h5) -> dict:
    """{path: object} of an open file's root and every group and dataset below it; the error of
    the first that cannot be opened is raised (walk_objects)."""
    objects, failures = walk_objects(h5)
    if failures:
        raise next(iter(failures.values()))
    return objects


def content_digest(h5, skip: tuple = ("checksum",), arrays: dict | None = None) -> str:
    """SHA-256 (hex) over everything an HDF5 file holds: every group's and dataset's path and
    attributes (but those named in `skip` on the root) and every dataset's dtype, shape and
    bytes. `arrays` ({path: array}): data already read, used instead of reading it again."""
    h = hashlib.sha256()
    objects = all_objects(h5)
    for path in sorted(objects):
        obj = objects[path]
        h.update(f"[{path}]".encode("utf-8", "surrogatepass"))
        names = sorted(obj.attrs.keys())
        for name in names:
            if path == "/" and name in skip:
                continue
            try:
                value = obj.attrs[name]
            except (OSError, RuntimeError, KeyError, ValueError, TypeError) as err:
                raise DamagedFileError(f"{h5.filename}:{path}: attribute {name!r} cannot be read "
                                       f"({_short(err)})") from None
            h.update(name.encode("utf-8", "surrogatepass") + b"=" + value_bytes(value) + b";")
        if isinstance(obj, h5py.Dataset):
            data = arrays[path] if arrays is not None and path in arrays else read(obj)
            h.update(b"data=" + value_bytes(data))
    return h.hexdigest()


def checked_dataset(group, name: str, data: np.ndarray, **options):
    """A dataset with Fletcher-32 per chunk (an empty one, which cannot be chunked, is covered by
    its seal instead). Chunked, in a file without a chunk cache, its data is written by this call:
    a full disk raises here, never later when the handle is freed (a small contiguous dataset waits
    in HDF5's sieve buffer until then, where the error is only printed)."""
    if data.size == 0:
        return group.create_dataset(name, data=data)
    return group.create_dataset(name, data=data, chunks=options.pop("chunks", True), fletcher32=True, **options)
