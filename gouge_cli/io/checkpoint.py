"""Checkpoints: every evolving array plus the config and callback state, written atomically.

A checkpoint is an HDF5 file: datasets ``state/<name>`` (see State.EVOLVING) and, with fluid,
``fluid/<name>``; states attached to it (the slip recorder's pre-slip ring, see driver/slips.py) under
``attached/<key>/{state,fluid}/<name>`` with their own ``extra`` attribute; attributes
``config`` (YAML of the validated config), ``extra`` (JSON: the :class:`CheckpointHeader` fields
io may read, and under ``states`` each callback's state by its name, read only by
:meth:`gouge_cli.driver.phase.Phase.restore`; older files' flat extra is mapped onto the two,
:func:`split_extra`), ``provenance`` (JSON, see :mod:`gouge_cli.io.provenance`) and ``checksum``:
``sha256-v2:`` and the SHA-256 over everything else the file holds, every dataset's path,
dtype, shape and bytes and every attribute of every group and dataset (config and extra
included; :func:`gouge_cli.io.integrity.content_digest`). A checkpoint written before that
(a bare hex digest, over the datasets alone) is still read, its datasets checked. It is written to a temporary file in the same
directory and renamed over the target, so a crash never leaves a half-written checkpoint behind; a
temporary file left by a killed writer (``.NAME.tmpPID`` of a process no longer alive) is
removed by the next write of that checkpoint.
"""

from __future__ import annotations

import io
import json
import os
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import h5py
import numpy as np
import yaml

from .. import __version__
from . import provenance
from ..config import build_config, Config, dump_config
from ..errors import CheckpointError, ConfigError, DamagedFileError
from .filedoc import document_checkpoint
from .integrity import content_digest
from .outputs import write_file
from .recovery import SeriesTail
from .rundir import pid_alive


SLIP_RECORDER = "slip_recorder"     # the slip recorder's name (driver.slips): its state's key
LEGACY_START = "compaction_start"   # where checkpoints before the callback model keep compaction's [t0, step0]
SETTLING = "settling"               # the name of compaction's settling callback (driver.compaction)
STATES = "states"                   # the key of the callback states in the extra attribute


@dataclass(frozen=True)
class CheckpointHeader:
    """What io and the studies may read of a checkpoint (its callbacks' states are Phase.restore's).

    phase        'compaction' or 'loading' (latest.h5); None: a state kept in memory (ring, slip)
    slips        slips the run had recorded when the state was taken (a resume keeps that many)
    series_tail  the series rows latest.h5 lines up with (loading; io.recovery)
    slip         the slip whose pre-slip state this is (checkpoints/slip_NNN.h5)
    onset_time   [t0] that slip's onset
    """

    phase: str | None = None
    slips: int = 0
    series_tail: SeriesTail | None = None
    slip: int | None = None
    onset_time: float | None = None

    def to_dict(self) -> dict:
        """The JSON fields (those not set left out)."""
        out = {"phase": self.phase, "slips": self.slips, "slip": self.slip, "onset_time": self.onset_time,
               "series_tail": asdict(self.series_tail) if self.series_tail is not None else None}
        return {key: value for key, value in out.items() if value is not None}

    @classmethod
    def from_dict(cls, record: dict) -> "CheckpointHeader":
        tail = record.get("series_tail")
        return cls(record.get("phase"), int(record.get("slips", 0)),
                   None if tail is None else SeriesTail(int(tail["rows"]), dict(tail["digests"])),
                   None if record.get("slip") is None else int(record["slip"]),
                   None if record.get("onset_time") is None else float(record["onset_time"]))


HEADER_FIELDS = tuple(f.name for f in fields(CheckpointHeader))


def split_extra(extra: dict) -> tuple[CheckpointHeader, dict]:
    """(header, {callback name: state}) of a stored extra: {header fields, "states": {...}}; the
    flat extra of older files (header fields and callback states side by side, the recorded slips
    in the recorder's state, compaction's start under LEGACY_START) is mapped onto the two."""
    if STATES in extra:
        return CheckpointHeader.from_dict(extra), dict(extra[STATES])
    states = {key: value for key, value in extra.items() if key not in HEADER_FIELDS and key != LEGACY_START}
    header = dict(extra, slips=int(states.get(SLIP_RECORDER, {}).get("count", 0)))
    if LEGACY_START in extra and SETTLING not in states:
        states[SETTLING] = {"start": extra[LEGACY_START]}
    return CheckpointHeader.from_dict(header), states


@dataclass
class Checkpoint:
    """A saved state: the scene's evolving arrays, its header (io's) and its callbacks' states.

    state     State.arrays(): grains (N,), pairs (npairs,), wall, clock, counters
    fluid     FluidGrid.arrays() ({} when dry or not started)
    header    what io reads (CheckpointHeader)
    states    {callback name: state}, put back by driver.phase.Phase.restore only
    attached  key -> Checkpoint (same config) kept with it: the slip recorder's ring
    """

    config: Config
    state: dict
    fluid: dict
    header: CheckpointHeader = field(default_factory=CheckpointHeader)
    states: dict = field(default_factory=dict)
    path: Path | None = None
    provenance: dict = field(default_factory=dict)
    attached: dict = field(default_factory=dict)

    @property
    def time(self) -> float:
        return float(self.state["clock"][0])

    @property
    def step(self) -> int:
        return int(self.state["counters"][0])


def _stored_extra(checkpoint: Checkpoint) -> str:
    """The extra attribute (JSON): the header's fields and the states under "states"."""
    return json.dumps({**checkpoint.header.to_dict(), STATES: checkpoint.states}, default=_plain)


def _plain(value):
    """json default: numpy scalars and arrays as Python numbers and lists."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot store {type(value).__name__} in a checkpoint")


def snapshot_of(sim, header: CheckpointHeader | None = None, states: dict | None = None,
                attached: dict | None = None) -> Checkpoint:
    """In-memory copy of the simulation's evolving state (cheap enough to keep a few), with its
    header, callback states ({name: state}) and attached checkpoints."""
    fluid = sim.fluid.arrays() if sim.fluid is not None else {}
    return Checkpoint(sim.config, sim.state.arrays(), fluid, header or CheckpointHeader(), dict(states or {}),
                      provenance=provenance.collect(sim.threads), attached=dict(attached or {}))


def state_bytes(sim) -> int:
    """Bytes of one checkpointed state of the simulation (grains, contacts, fluid grid)."""
    fluid = sim.fluid.arrays() if sim.fluid is not None else {}
    return sum(a.nbytes for a in sim.state.arrays().values()) + sum(a.nbytes for a in fluid.values())


def _groups(checkpoint: Checkpoint) -> dict[str, dict[str, np.ndarray]]:
    """HDF5 group path -> arrays, the attached states included."""
    groups = {"state": checkpoint.state, "fluid": checkpoint.fluid}
    for key, child in checkpoint.attached.items():
        groups[f"attached/{key}/state"] = child.state
        groups[f"attached/{key}/fluid"] = child.fluid
    return groups


def remove_stale_temps(path: Path) -> list[Path]:
    """Remove ``.NAME.tmpPID`` files next to `path` left by writers that are no longer alive."""
    removed = []
    for tmp in Path(path).parent.glob(f".{Path(path).name}.tmp*"):
        pid = tmp.name.rsplit(".tmp", 1)[1]
        if pid.isdigit() and int(pid) != os.getpid() and not pid_alive(int(pid)):
            tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


def write_checkpoint(path: Path, checkpoint: Checkpoint) -> float:
    """Write atomically; returns the file size in bytes. The file is built in memory and then
    written as plain bytes, so a full disk is an OSError of that write (HDF5 writing onto a full
    disk failed inside freed handles, where its errors are ignored, and crashed the process)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    groups = _groups(checkpoint)
    image = io.BytesIO()
    try:
        with h5py.File(image, "w") as h5:
            for group, arrays in groups.items():
                g = h5.create_group(group)
                for name, arr in arrays.items():
                    g.create_dataset(name, data=arr)
            for key, child in checkpoint.attached.items():
                h5[f"attached/{key}"].attrs["extra"] = _stored_extra(child)
            h5.attrs["config"] = dump_config(checkpoint.config)
            h5.attrs["extra"] = _stored_extra(checkpoint)
            h5.attrs["version"] = __version__
            h5.attrs["provenance"] = provenance.dumps(checkpoint.provenance or provenance.collect())
            h5.attrs["checksum"] = ""          # set below; named in attribute_units
            document_checkpoint(h5)
            arrays = {f"/{group}/{name}": arr for group, named in groups.items() for name, arr in named.items()}
            h5.attrs["checksum"] = DIGEST_PREFIX + content_digest(h5, arrays=arrays)
        write_file(tmp, image.getbuffer())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path.stat().st_size


DIGEST_PREFIX = "sha256-v2:"


def _verify(h5, path: Path, groups: dict, checksum) -> None:
    """CheckpointError unless `checksum` matches the file (`groups`: its datasets, already read)."""
    checksum = checksum.decode() if isinstance(checksum, bytes) else str(checksum)
    if checksum.startswith(DIGEST_PREFIX):
        arrays = {f"/{group}/{name}": arr for group, named in groups.items() for name, arr in named.items()}
        if content_digest(h5, arrays=arrays) != checksum[len(DIGEST_PREFIX):]:
            raise CheckpointError(f"checkpoint {path} is corrupt: its contents (datasets, config, extra or other "
                                  "attributes) do not match its checksum; nothing was computed from it")
        return
    if len(checksum) != 64 or provenance.state_digest(dict(groups, fluid=groups.get("fluid", {}))) != checksum:
        raise CheckpointError(f"checkpoint {path} is corrupt: its checksum does not match its contents; nothing "
                              "was computed from it")


def read_checkpoint(path: Path, overrides: list[str] | dict | None = None) -> Checkpoint:
    """Load and verify a checkpoint; its config plus `overrides` is re-validated."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        with h5py.File(path, "r") as h5:
            groups = {g: {name: ds[...] for name, ds in h5[g].items()} for g in ("state", "fluid") if g in h5}
            keys = sorted(h5["attached"]) if "attached" in h5 else []
            child_extra = {}
            for key in keys:
                for part in ("state", "fluid"):
                    g = h5[f"attached/{key}/{part}"]
                    groups[f"attached/{key}/{part}"] = {name: ds[...] for name, ds in g.items()}
                child_extra[key] = h5[f"attached/{key}"].attrs["extra"]
            _verify(h5, path, groups, h5.attrs["checksum"])
            config_text = h5.attrs["config"]
            extra = json.loads(h5.attrs["extra"])
            stored = provenance.loads(h5.attrs.get("provenance"))
            child_extra = {key: json.loads(text) for key, text in child_extra.items()}
    except CheckpointError:
        raise
    except DamagedFileError as err:
        raise CheckpointError(f"checkpoint {path} is corrupt: {err}; nothing was computed from it") from None
    except (OSError, KeyError, ValueError, RuntimeError, TypeError) as err:
        raise CheckpointError(f"checkpoint {path} is unreadable or truncated ({str(err)[:200]})") from None
    groups.setdefault("fluid", {})
    try:
        config = build_config(yaml.safe_load(config_text), overrides)
    except ConfigError as err:
        raise ConfigError(f"{err}") from None
    except yaml.YAMLError as err:
        raise CheckpointError(f"checkpoint {path}: its config attribute is not valid YAML "
                              f"({str(err).splitlines()[0][:160]})") from None
    attached = {key: Checkpoint(config, groups[f"attached/{key}/state"], groups[f"attached/{key}/fluid"],
                                *split_extra(child_extra[key]), provenance=stored) for key in keys}
    return Checkpoint(config, groups["state"], groups["fluid"], *split_extra(extra), path, provenance=stored,
                      attached=attached)
