"""The loading cycle against the normal stress (issue 63): each run's stress drop and recurrence,
and whether the recurrence is the time the spring takes to give the drop back.

A spring of stiffness k per unit wall length [E/d] pulled at V [v0] reloads a wall of length L
by a stress drop drop x sigma (drop in tau/sigma, sigma [E]) in drop sigma L / (k L V) =
drop sigma / (k V) [t0]: the wall's length cancels. A run's row in the campaign table carries
that prediction for its mean drop (``recurrence_reload``) and the measured mean recurrence over
it (``recurrence_ratio``), both from
:func:`~gouge_cli.analysis.campaign_table.reload_columns`, the one owner of the formula; the
results record of a run holds the mean and std of its slips' drops and recurrences (transient
slips included: the record keeps the run's statistics, not its catalog), and its slip count.

A run *stick-slips* when it has at least :data:`MIN_SLIPS` slips (a recurrence needs two); with
none it slid steadily (or crept) for its whole length, with one it has no recurrence. Such runs
are kept and counted, never dropped. Per normal stress, the seed is the unit (one run per seed):
the means over the stick-slipping runs with the Student-t 95 % interval over seeds
(:func:`~gouge_cli.analysis.seedboot.seed_mean`; NaN bounds for one seed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .regime import Estimate
from .seedboot import seed_mean

__all__ = ["MIN_SLIPS", "SIGMA_KEY", "RunCycle", "SigmaCycle", "run_cycles", "sigma_cycles", "RECURRENCE_COLUMNS"]

#: the fewest slips of a run that stick-slips (a recurrence is an onset less the previous one)
MIN_SLIPS = 2
#: the swept column of the normal stress [E]
SIGMA_KEY = "loading.normal_stress"
_NAN = float("nan")


def _num(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return _NAN


@dataclass(frozen=True)
class RunCycle:
    """One run's loading cycle (a run row of the campaign table).

    sigma [E]; n_slips: the run's slips; stress_drop: their mean drop [tau/sigma]; recurrence:
    their mean recurrence [t0]; predicted: drop sigma / (k V) [t0] for that mean drop; ratio:
    recurrence / predicted (NaN where the run has no recurrence)."""

    point: str
    seed: str
    sigma: float
    n_slips: int
    stress_drop: float
    recurrence: float
    predicted: float
    ratio: float

    @property
    def stick_slips(self) -> bool:
        return self.n_slips >= MIN_SLIPS and math.isfinite(self.ratio)

    @property
    def state(self) -> str:
        """'stick-slip', 'one slip' or 'steady' (no slip in the whole run)."""
        return "stick-slip" if self.stick_slips else ("steady" if self.n_slips == 0 else "one slip")


@dataclass(frozen=True)
class SigmaCycle:
    """The runs at one normal stress sigma [E]: how many stick-slip, and over those the means of
    the drop [tau/sigma], the recurrence and its prediction [t0] and their ratio, each with its
    Student-t 95 % interval over seeds (:class:`~gouge_cli.analysis.regime.Estimate`)."""

    sigma: float
    n_runs: int
    n_stick_slip: int
    n_one_slip: int
    n_steady: int
    stress_drop: Estimate
    recurrence: Estimate
    predicted: Estimate
    ratio: Estimate

    @property
    def state(self) -> str:
        """'stick-slip' (every run), 'steady' (no run has a recurrence) or 'mixed'."""
        if self.n_stick_slip == self.n_runs:
            return "stick-slip"
        return "steady" if self.n_stick_slip == 0 else "mixed"

    def csv_row(self) -> dict:
        row = {"sigma": self.sigma, "state": self.state, "n_runs": self.n_runs, "n_stick_slip": self.n_stick_slip,
               "n_one_slip": self.n_one_slip, "n_steady": self.n_steady}
        for name in _ESTIMATES:
            e = getattr(self, name)
            row[name], row[f"{name}_seed_lo"], row[f"{name}_seed_hi"] = e.value, e.seed_lo, e.seed_hi
        return row


_ESTIMATES = ("stress_drop", "recurrence", "predicted", "ratio")
#: columns of recurrence.csv
RECURRENCE_COLUMNS = ["sigma", "state", "n_runs", "n_stick_slip", "n_one_slip", "n_steady",
                      *[f"{n}{s}" for n in _ESTIMATES for s in ("", "_seed_lo", "_seed_hi")]]


def run_cycles(run_rows: list[dict], sigma_key: str = SIGMA_KEY) -> list[RunCycle]:
    """The :class:`RunCycle` of each run row (``kind`` 'run' of a campaign table, as built or read
    back from table.csv), its sigma from the swept column ``sigma_key``."""
    out = []
    for r in run_rows:
        if r.get("kind", "run") != "run":
            continue
        if sigma_key not in r:
            raise KeyError(f"run row of {r.get('point', '?')} has no column {sigma_key!r} (not swept?)")
        n = int(_num(r.get("n_slips")) if math.isfinite(_num(r.get("n_slips"))) else 0)
        ratio = _num(r.get("recurrence_ratio")) if n >= MIN_SLIPS else _NAN
        out.append(RunCycle(str(r.get("point", "")), str(r.get("seed", "")), _num(r[sigma_key]), n,
                            _num(r.get("stress_drop_mean")), _num(r.get("recurrence_mean")),
                            _num(r.get("recurrence_reload")), ratio))
    return out


def sigma_cycles(runs: list[RunCycle]) -> list[SigmaCycle]:
    """One :class:`SigmaCycle` per normal stress, in increasing sigma; a sigma whose runs all
    slide steadily is kept (NaN means, ``state`` 'steady')."""
    out = []
    for sigma in sorted({r.sigma for r in runs}):
        at = [r for r in runs if r.sigma == sigma]
        slipping = [r for r in at if r.stick_slips]

        def mean(name: str) -> Estimate:
            return Estimate(*seed_mean([getattr(r, name) for r in slipping]))

        out.append(SigmaCycle(sigma, len(at), len(slipping), sum(r.state == "one slip" for r in at),
                              sum(r.state == "steady" for r in at), *(mean(n) for n in _ESTIMATES)))
    return out
