"""Campaign results that outlive the machine: one small JSON record per finished piece.

Layout of a campaign's results folder (``<out>/<name>/results`` unless the spec's ``results``
names another)::

    <point>/run.json          the loading run: swept values, slips kept with checkpoints, the
                              transient slips, the run's table row, its final state hash
    <point>/fork_NNN.json     the forks of slip NNN: one table row per pair (every variant and
                              permeability) and the final state hash of every branch

Every record names its campaign, point and piece, the settings the piece ran with and their
digest, gouge's commit, the CPU and numba target, and the wall time: a few kilobytes, to be
copied and committed beside the spec. The campaign's tables are built from these records alone
(:mod:`gouge_cli.workflows.campaign_tables`), so a machine that holds the results but not the run
folders runs only what is missing, and two results folders of one spec merge (:func:`merge`;
a record made with other settings is refused, naming the key).
"""

from __future__ import annotations

import json
import os
import socket
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..errors import CampaignConflict, InputError

SCHEMA = "gouge.campaign-result/1"
RUN_PIECE = "run"


def fork_piece(slip: int) -> str:
    """The label of slip ``slip``'s fork piece (its ledger and its record are named after it)."""
    return f"fork_{slip:03d}"


def settings_digest(settings: dict) -> str:
    """16 hex digits of the SHA-256 of the settings as sorted JSON (what a piece's results depend on)."""
    import hashlib

    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def diff_keys(old, new, prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two nested dicts, as 'key: old -> new'."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(old) | set(new), key=str):
            out += diff_keys(old.get(key), new.get(key), f"{prefix}{key}.")
        return out
    return [] if old == new else [f"{prefix[:-1]}: {old!r} -> {new!r}"]


def machine() -> dict:
    """Where a piece ran: gouge's commit and version, the CPU, numba's target, the host."""
    from ..io import provenance

    cpu = provenance.cpu()
    return {"git_commit": provenance.git_commit(), "gouge_version": provenance.libraries()["gouge"],
            "cpu": cpu["model"], "numba_target": cpu["numba_target"], "vector_width_bits": cpu["vector_width_bits"],
            "host": socket.gethostname()}


@dataclass(frozen=True)
class PieceRecord:
    """The results of one finished piece.

    point, piece   the sweep point and the piece label ('run' or 'fork_NNN')
    settings       what the results depend on (the ledger's settings); ``digest`` their hash
    result         run: {values, n_slips, slips, transient, row, final_state_hash};
                   fork: {slip, pairs: [pair rows], branches: {folder: final_state_hash}}
    machine        :func:`machine` of the worker that ran it
    wall_seconds   the piece's wall time [s]; ``finished``: when it ended (Unix time)
    cpu_seconds    the worker process's CPU time over the piece [s] (0: a record from before it was kept)
    """

    campaign: str
    point: str
    piece: str
    settings: dict
    result: dict
    machine: dict = field(default_factory=machine)
    wall_seconds: float = 0.0
    finished: float = field(default_factory=time.time)
    cpu_seconds: float = 0.0
    schema: str = SCHEMA

    @property
    def digest(self) -> str:
        return settings_digest(self.settings)

    def to_json(self) -> str:
        return json.dumps({**asdict(self), "digest": self.digest}, indent=1, allow_nan=True)     # (key order kept:
        # the table's columns follow it, read back or not)

    @classmethod
    def from_json(cls, text: str, where: Path | str = "") -> PieceRecord:
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise InputError(f"{where}: not a campaign result record ({exc})") from None
        if not isinstance(data, dict) or data.get("schema") != SCHEMA:
            raise InputError(f"{where}: not a campaign result record (schema {SCHEMA!r} expected)")
        data.pop("digest", None)
        try:
            return cls(**data)
        except TypeError as exc:
            raise InputError(f"{where}: campaign result record with unexpected fields ({exc})") from None


class Results:
    """A campaign's results folder: records by (point, piece)."""

    def __init__(self, root: Path | str):
        self.root = Path(root)

    def path(self, point: str, piece: str) -> Path:
        return self.root / point / f"{piece}.json"

    def write(self, record: PieceRecord) -> Path:
        """Write one record atomically (a kill leaves the old record or the new, never half)."""
        path = self.path(record.point, record.piece)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(record.to_json())
        os.replace(tmp, path)
        return path

    def read(self, point: str, piece: str) -> PieceRecord | None:
        path = self.path(point, piece)
        try:
            text = path.read_text()
        except OSError:
            return None
        return PieceRecord.from_json(text, path)

    def records(self) -> dict[tuple[str, str], PieceRecord]:
        """Every record present, by (point, piece)."""
        out = {}
        if self.root.is_dir():
            for path in sorted(self.root.glob("*/*.json")):
                record = PieceRecord.from_json(path.read_text(), path)
                out[(record.point, record.piece)] = record
        return out


def merge(ours: Results, theirs: Results, campaign: str) -> list[Path]:
    """Copy into ``ours`` the records of ``theirs`` that it lacks. Refuses (CampaignConflict,
    nothing copied) a record of another campaign or one whose settings differ from ours for the
    same piece, naming the keys. Returns the paths written."""
    mine = ours.records()
    other = theirs.records()
    if not other:
        raise InputError(f"{theirs.root}: no campaign result records (<point>/run.json, <point>/fork_NNN.json)")
    problems, todo = [], []
    for key, record in sorted(other.items()):
        if record.campaign != campaign:
            problems.append(f"  {record.point} {record.piece}: of campaign {record.campaign!r}, not {campaign!r}")
            continue
        have = mine.get(key)
        if have is None:
            todo.append(record)
        elif have.digest != record.digest:
            changed = "; ".join(diff_keys(have.settings, record.settings))
            problems.append(f"  {record.point} {record.piece}: settings differ: {changed}")
    if problems:
        raise CampaignConflict(f"cannot merge {theirs.root} into {ours.root}: {len(problems)} records conflict, "
                               "nothing was copied:\n" + "\n".join(problems))
    return [ours.write(r) for r in todo]


__all__ = ["SCHEMA", "PieceRecord", "Results", "merge", "machine", "settings_digest", "diff_keys", "fork_piece"]
