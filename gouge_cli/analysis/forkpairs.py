"""Drained/undrained fork pairs of a run: the forks under RUN/forks/slip_NNN/, their first slips
classified with the pair definition of analysis.pairs, and the campaign summary over them."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import AnalysisError, DamagedFileError, NotARunError
from ..io.runfile import RunInfo, RunReader
from .catalog import nan_mean, wall_series
from .pairs import PairDefinition, PairResult, campaign_summary, classify_pair

_NAN = float("nan")


PAIR_COLUMNS = (
    "run", "slip", "branch", "permeability", "main", "type", "base_type", "complex", "criteria",
    "undrained_event", "drained_strength", "undrained_strength", "strength_difference",
    "peak_velocity_ratio", "stress_drop_ratio", "duration_ratio", "drained_peak_over_Vs",
    "undrained_peak_over_Vs", "n_undrained_slips", "n_subevents", "drained_onset", "drained_end",
    "undrained_onset", "undrained_end", "drained_fit_r2", "drained_fit_ok", "undrained_fit_r2",
    "deborah_mean", "note",
)



def fork_dirs(run_dir: Path) -> list[Path]:
    """``RUN/forks/slip_NNN`` directories, in slip order."""
    root = Path(run_dir) / "forks"
    return sorted(p for p in root.glob("slip_*") if p.is_dir()) if root.is_dir() else []



def fork_branches(fork_dir: Path) -> tuple[Path | None, list[Path]]:
    """(drained run dir or None, undrained ``perm_*`` run dirs sorted by permeability)."""
    fork_dir = Path(fork_dir)
    drained = fork_dir / "drained"
    perms = [p for p in fork_dir.glob("perm_*") if (p / "run.h5").is_file()]

    def perm_value(p: Path) -> float:
        try:
            return float(p.name[len("perm_"):])
        except ValueError:
            return math.inf

    return (drained if (drained / "run.h5").is_file() else None), sorted(perms, key=perm_value)



@dataclass
class ForkPair:
    """One drained/undrained pair: the table row (:data:`PAIR_COLUMNS`) and the classification."""

    row: dict
    result: PairResult
    drained_dir: Path
    undrained_dir: Path



def _r2(fit) -> float:
    return float(fit.r2) if fit is not None else _NAN



def _when(slip, attr: str) -> float:
    return float(getattr(slip, attr)) if slip is not None else _NAN



def pair_definition(info: RunInfo, main: str = "first") -> PairDefinition:
    """The pair definition with this run's detector thresholds."""
    return PairDefinition.for_run(info.slip_params, main=main)



def classify_fork(fork_dir: Path, main: str = "first") -> list[ForkPair]:
    """Classify every undrained branch of ``RUN/forks/slip_NNN`` against its drained branch.

    Uses :func:`~gouge_cli.analysis.pairs.classify_pair` with :func:`pair_definition` (the run's
    detector thresholds; ``main``: "first" or "largest"). Raises :class:`RunStillRunningError`
    when a branch is still running and :class:`NotARunError` when the drained branch is missing.
    """
    fork_dir = Path(fork_dir)
    drained_dir, undrained_dirs = fork_branches(fork_dir)
    if drained_dir is None:
        raise NotARunError(f"{fork_dir} has no drained/run.h5; run `gouge restart` for this slip again")
    pairs = []
    with RunReader(drained_dir) as d:
        info = d.info
        drained = wall_series(d)
        definition = pair_definition(info, main)
        for udir in undrained_dirs:
            with RunReader(udir) as u:
                undrained = wall_series(u)
                deborah = u.series(["deborah"])["deborah"]
                uinfo = u.info
            result = classify_pair(drained, undrained, info.V_s, info.k, info.m_b, info.sigma, definition)
            d_main, u_main = result.drained_slip, result.undrained_slip
            fired = [name for name, on in result.criteria.items() if on]
            parent = str(fork_dir.parent.parent)     # parent_run is stored relative to the branch
            row = {
                "run": parent,
                "slip": int(info.fork_slip) if info.fork_slip is not None else _slip_number(fork_dir),
                "branch": udir.name,
                "permeability": uinfo.permeability if uinfo.permeability is not None else _NAN,
                "main": definition.main,
                "type": result.type,
                "base_type": result.base_type,
                "complex": bool(result.complex),
                "criteria": ",".join(fired),
                "undrained_event": result.undrained_event,
                "drained_strength": result.drained_strength,
                "undrained_strength": result.undrained_strength,
                "strength_difference": result.strength_difference,
                "peak_velocity_ratio": result.peak_velocity_ratio,
                "stress_drop_ratio": result.stress_drop_ratio,
                "duration_ratio": result.duration_ratio,
                "drained_peak_over_Vs": result.drained_peak_over_Vs,
                "undrained_peak_over_Vs": result.undrained_peak_over_Vs,
                "n_undrained_slips": len(result.undrained_slips),
                "n_subevents": result.n_subevents,
                "drained_onset": _when(d_main, "onset_time"),
                "drained_end": _when(d_main, "end_time"),
                "undrained_onset": _when(u_main, "onset_time"),
                "undrained_end": _when(u_main, "end_time"),
                "drained_fit_r2": _r2(result.drained_fit),
                "drained_fit_ok": bool(result.drained_fit is not None and result.drained_fit.success),
                "undrained_fit_r2": _r2(result.undrained_fit),
                "deborah_mean": nan_mean(deborah),
                "note": result.note,
            }
            pairs.append(ForkPair(row, result, drained_dir, udir))
    return pairs



def _slip_number(fork_dir: Path) -> int:
    try:
        return int(Path(fork_dir).name.split("_")[-1])
    except ValueError:
        return -1



def run_pairs(run_dir: Path, strict: bool = False, main: str = "first") -> tuple[list[ForkPair], list[str]]:
    """All pairs under ``RUN/forks`` (compared events chosen by ``main``). Returns (pairs, skipped):
    a fork that cannot be classified (still running, incomplete, damaged) is skipped with its reason, or
    raises when ``strict``."""
    pairs, skipped = [], []
    for fork in fork_dirs(run_dir):
        try:
            pairs.extend(classify_fork(fork, main))
        except (AnalysisError, DamagedFileError) as exc:      # a damaged branch is skipped, named
            if strict:
                raise
            skipped.append(str(exc))
    return pairs, skipped



def campaign(pairs: list[ForkPair]) -> dict:
    """Counts per type and undrained/drained ratio statistics over pairs (of one or more runs)."""
    return campaign_summary([p.result for p in pairs])
