"""Compaction's settling criterion, and how far a compaction is from meeting it.

Compaction (driver.compaction) ends, on one of its checks every 100 t0, when

    elapsed >= compaction.min_time  and  |v_wall,z| < v_tol  and  v_rms < v_tol,

v_tol = compaction.wall_velocity_tol * sigma [v0] and v_rms the rms speed of the free grains,
or gives up at compaction.max_time. :class:`SettleCheck` is one such check; :class:`SettleTracker`
turns successive checks into a progress fraction and an ETA toward that criterion (not toward
max_time): the speeds decay roughly exponentially while the layer settles, so the remaining
time is extrapolated from the recent slope of ln(max(|v_wall,z|, v_rms) / v_tol) against time.
Only observes: nothing here changes the simulation.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class SettleCheck:
    """One check of the criterion. elapsed, min_time [t0]; wall_vz, rms, v_tol [v0]."""

    elapsed: float
    wall_vz: float
    rms: float
    v_tol: float
    min_time: float

    @property
    def ratio(self) -> float:
        """max(|v_wall,z|, v_rms) / v_tol: the speed criterion holds when this is < 1."""
        return max(abs(self.wall_vz), self.rms) / self.v_tol

    @property
    def settled(self) -> bool:
        return self.elapsed >= self.min_time and abs(self.wall_vz) < self.v_tol and self.rms < self.v_tol

    def unmet(self) -> list[str]:
        """The conditions still unmet, in words (empty once settled)."""
        out = []
        if self.elapsed < self.min_time:
            out.append(f"min_time ({self.elapsed:.4g} / {self.min_time:.4g} t0)")
        if abs(self.wall_vz) >= self.v_tol:
            out.append(f"|wall vz| = {abs(self.wall_vz) / self.v_tol:.3g} v_tol")
        if self.rms >= self.v_tol:
            out.append(f"rms grain speed = {self.rms / self.v_tol:.3g} v_tol")
        return out


def settle_check(state, kinetic_energy: float, wall_vz: float, elapsed: float, v_tol: float,
                 min_time: float) -> SettleCheck:
    """The check of a state: v_rms = sqrt(2 KE / (N_free <m>)) over the free grains (body 0),
    KE [E d^2 ... as kernels.measure.observe] the kinetic energy of the observation row."""
    n_free = max(1, int((state.body == 0).sum()))
    rms = math.sqrt(2.0 * kinetic_energy / (n_free * float(state.mass.mean())))
    return SettleCheck(float(elapsed), float(wall_vz), rms, float(v_tol), float(min_time))


class SettleTracker:
    """Progress fraction and ETA toward settling from successive checks.

    fraction = min(f_time, f_speed): f_time = elapsed / min_time (capped at 1); f_speed =
    1 - ln r / ln r_max, r = SettleCheck.ratio and r_max the largest r seen (1 once r < 1).
    Both reach 1 exactly on the check that settles. ETA: the remaining simulated time is the
    larger of min_time - elapsed and ln r / (-d ln r / dt), the slope fitted (least squares) to
    the last `window` checks with r >= 1; capped at max_time - elapsed, where compaction stops
    anyway, and rounded up to the next check (every `check_every` t0). It is converted to wall
    seconds at the recent wall time per t0.
    """

    def __init__(self, max_time: float, check_every: float = 100.0, window: int = 5):
        self.max_time, self.check_every = float(max_time), float(check_every)
        self.r_max = 1.0
        self._recent: deque = deque(maxlen=max(2, window))        # (elapsed, ln r) with r >= 1
        self._clock: deque = deque(maxlen=max(2, window))         # (elapsed, wall seconds)

    def update(self, check: SettleCheck, wall_seconds: float) -> dict:
        """Feed one check made `wall_seconds` after some fixed origin. Returns fraction [0, 1],
        remaining [t0] and eta [s] (inf when no decay is seen yet and no cap applies),
        capped (True when the ETA is the time left to max_time), unmet (list of words)."""
        r = check.ratio
        self.r_max = max(self.r_max, r)
        log_r = math.log(r) if r > 0 else -math.inf
        f_time = min(1.0, check.elapsed / check.min_time) if check.min_time > 0 else 1.0
        f_speed = 1.0 if r < 1.0 else (1.0 - log_r / math.log(self.r_max) if self.r_max > 1.0 else 0.0)
        if r >= 1.0:
            self._recent.append((check.elapsed, log_r))
        self._clock.append((check.elapsed, wall_seconds))
        fraction = 1.0 if check.settled else min(f_time, f_speed, math.nextafter(1.0, 0.0))
        left_time = max(0.0, check.min_time - check.elapsed)
        left_speed = 0.0 if r < 1.0 else self._speed_time_left(log_r)
        remaining = max(left_time, left_speed)
        if math.isfinite(remaining):        # it can only settle on a check
            remaining = math.ceil(remaining / self.check_every - 1e-9) * self.check_every
        cap = max(0.0, self.max_time - check.elapsed)
        capped = remaining > cap
        remaining = 0.0 if check.settled else min(remaining, cap)
        return {"fraction": fraction, "remaining": remaining, "eta": remaining * self._wall_per_t0(),
                "capped": capped, "unmet": check.unmet()}

    def _speed_time_left(self, log_r: float) -> float:
        """ln r / (-slope) of ln r against elapsed over the recent checks; inf without decay."""
        pts = list(self._recent)
        if len(pts) < 2:
            return math.inf
        t_mean = sum(p[0] for p in pts) / len(pts)
        y_mean = sum(p[1] for p in pts) / len(pts)
        den = sum((p[0] - t_mean) ** 2 for p in pts)
        slope = sum((p[0] - t_mean) * (p[1] - y_mean) for p in pts) / den if den > 0 else 0.0
        return log_r / -slope if slope < 0 else math.inf

    def _wall_per_t0(self) -> float:
        """Wall seconds per simulated t0 over the recent checks (from the origin with one)."""
        (t_a, w_a), (t_b, w_b) = (self._clock[0] if len(self._clock) > 1 else (0.0, 0.0)), self._clock[-1]
        return (w_b - w_a) / (t_b - t_a) if t_b > t_a else 0.0
