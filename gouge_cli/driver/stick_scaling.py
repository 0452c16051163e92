"""Stick-phase inertia (density) scaling of loading runs (docs/physics/stick_scaling.md, issue 19).

While a loading run sticks, the mass and moment of inertia of every grain and the mass of the
top wall are multiplied by lambda (``numerics.stick_scaling``); the step is the true step times
sqrt(lambda), so the stability margin (timestep.py) is unchanged, and the dashpot rate
(material.damping, a rate: F = -gamma m_ij v_n, thesis Eq. 8) is divided by sqrt(lambda), which
keeps the damping ratio gamma m / (2 sqrt(k m)) and the dashpot's stability (gamma dt) as they
are. Forces, the contact law and the loading are unchanged. Only loading runs with
``numerics.stick_scaling > 1`` are scaled: compaction, forks (workflows.fork.branch_config sets
lambda = 1) and every slip run at true inertia.

Rules of :class:`StickScaling` (checked on every time-series row):

* **Onset.** A slip's velocities are sqrt(lambda) times smaller with scaled inertia (block
  slider: v_peak ~ dtau / sqrt(k m)), so a scaled stretch ends at the first row with
  v_wall >= max(end_factor, start_factor / sqrt(lambda)) V_s, or with tau/sigma more than
  slips.lead_stress / 4 below its peak since scaling (re)started. The run goes back to the
  slip recorder's pre-slip state (the newest ring state at least slips.lead before the onset
  estimate, driver.slips.SlipRecorder.choose_pre_slip; the oldest kept one if none is that old; never one
  from before scaling last resumed, whose state is put in the ring then, since the stretch
  before it was at true inertia already: so a run cannot loop). The controller asks for that
  rewind (after_row returns a :class:`Rollback`) and performs none: the loading phase puts the
  state back (driver.phase.Phase.restore with that ring state alone attached: the recorder and
  the energy guard as they were then, the ring holding that state alone, since an older one would
  not retrace the recomputation; rows, snapshots and catalog entries after it dropped,
  RunFile.truncate_after), then calls after_rewind: lambda becomes 1 and the run computes again
  from there. Without a kept state it switches to lambda = 1 where it is (``in_place``).
* **Resume.** Scaling resumes once the true-inertia stretch has moved (v_wall >= start_factor
  V_s, or tau/sigma lead_stress / 4 below its peak since the rollback), the slip detector has
  closed what it saw (no raw or pending event, no pending pre-slip state: the slip is in the
  catalog or dropped as too small) and the wall has then been quiet for
  quiet_window = max(slips.merge_gap + 2 output.series_interval, min(D, slips.lead)), D the
  duration of the last slip the detector closed in this stretch (0 if none; capped at the lead,
  the window of the first version, so that no scene waits longer than it did): no row with
  v_wall >= start_factor V_s,
  |mean wall velocity| over the window (displacement / time) and |v_wall| of the last row below
  end_factor V_s (the instantaneous wall velocity rattles above end_factor V_s in ~15 % of
  stick rows). The window is tied to the slip, not to slips.lead: the lead is spent at true
  inertia once per cycle, before the onset (the rollback), not a second time after the slip.
  At the resume the recorder's stress peak starts afresh (SlipRecorder.forget_peak): after a
  slow slip that never reached the trigger the old peak would keep the ring empty through the
  scaled stretch, and the next rollback would go back to the resume, recomputing the whole
  stretch at true inertia.
* **Miss.** If the recomputation reaches the scaled onset time + slips.lead without moving so,
  it is counted in ``misses`` and simply continues at lambda = 1 until it does.
* **Guard.** If, in a scaled stretch while the wall is quiet (v_wall < end_factor V_s), the
  inertial number I = (|v_wall| / H) d_mean sqrt(lambda rho / sigma) (or, wet, the stick
  Deborah number sqrt(lambda) De) exceeds its bound (numerics.stick_inertial_max,
  stick_deborah_max), lambda is lowered to lambda (bound / value / 2)^2 (1 below 2) until
  the next slip, and a line on stderr says so.
* **Switches.** When lambda changes without a rollback (resume, guard, a switch in place) the
  velocities of grains, spins and the top wall are multiplied by sqrt(lambda_old /
  lambda_new): the switch creates no kinetic energy. A rollback restores the stored state as
  it is (a fork from it then computes exactly the same), and the start of loading scales the
  settled packing with its (tiny) velocities as they are.
* **Wet runs.** Scaling slows the grains' response but not pressure diffusion: the scaled stick
  phase is the true one loaded sqrt(lambda) times faster, De_stick = sqrt(lambda) l V_s / D.
  A wet loading run whose De_stick exceeds numerics.stick_deborah_max is refused (ConfigError).

With lambda = 1 the mass arrays, step, wall mass and dashpot rate are recomputed with the very
expressions State and Simulation use, so the true-inertia stretches are bit for bit what an
unscaled run (and a fork) computes from the same state.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass

from ..config import Config
from ..errors import ConfigError
from ..io.checkpoint import Checkpoint
from ..kernels import layout as L
from ..model.portable import sphere_mass
from ..model.timestep import choose_dt
from .callbacks import Callback
from .slips import RING_PER_LEAD, SlipRecorder, lead_time

# The largest lambda the ladder found within the seed spread with every smaller rung
# (README: configs/scaling_long.yaml, 16 seeds: 64 fails on slip duration; 8 seeds had given 64).
# Not the shipped numerics.stick_scaling, which stays 1 (off): README says why.
LADDER_DEFAULT = 16.0
# a rollback lands at least one lead and at most one ring spacing more before the onset: 1.25 leads
ROLLBACK_LEADS = 1.0 + 1.0 / RING_PER_LEAD
STICK_SCALING = "stick_scaling"     # the controller's name (its state's key in a checkpoint)


def set_inertia(sim, lam: float, dt_true: float):
    """Scale grain mass, inv_mass, inv_inertia [N] and the wall mass by lambda, the step by
    sqrt(lambda) and the dashpot rate by 1/sqrt(lambda); lam = 1 gives exactly the arrays of
    State.__post_init__ and the params of model.params.build_params."""
    s = sim.state
    s.mass[...] = sphere_mass(s.radius, s.density * lam)
    s.inv_mass[...] = 1.0 / s.mass
    s.inv_inertia[...] = 1.0 / (s.mass * (2.0 * s.radius) ** 2 / 10.0)
    s.list_changed()
    sim.dt = dt_true * math.sqrt(lam)
    sim.params[L.DT] = sim.dt
    sim.params[L.WALL_MASS] = sim.wall_mass_per_length * s.width * lam
    sim.params[L.DAMPING] = sim.config.material.damping / math.sqrt(lam)
    sim.inertia_scale = lam


def quiet_floor(config: Config) -> float:
    """Shortest quiet window before scaling resumes [t0]: slips.merge_gap + 2 series intervals
    (the detector closes a slip merge_gap after its end; two rows more for the row cadence)."""
    return config.slips.merge_gap + 2.0 * config.output.series_interval


def quiet_window(floor: float, slip: float, lead: float) -> float:
    """Quiet time [t0] before scaling resumes after a slip of duration `slip` (module docstring)."""
    return max(floor, min(slip, lead))


def stick_deborah_bound(config: Config, lam: float, diffusivity: float, half_thickness: float) -> float:
    """De_stick = sqrt(lambda) l V_s / D [-] of a wet loading run (l: half the layer [d])."""
    return math.sqrt(lam) * half_thickness * config.loading.velocity / max(diffusivity, 1e-300)


@dataclass(frozen=True)
class Rollback:
    """after_row's request at a scaled onset: put ring state ``to`` back (Phase.restore), then call
    after_rewind; ``to`` None: no state was kept, the run switched to lambda = 1 where it is."""

    to: Checkpoint | None


class TrueInertia(Callback):
    """Stick scaling off (numerics.stick_scaling = 1): the controller's interface at lambda = 1
    throughout (no columns, never a rollback, nothing saved)."""

    name = STICK_SCALING

    def columns(self, sim, row: dict) -> dict:
        return {}

    def after_row(self, sim, row: dict, recorder: SlipRecorder, slip=None) -> Rollback | None:
        return None

    def after_rewind(self, sim) -> None:
        pass

    def finish(self, sim, writer) -> None:
        pass


def controller(config: Config, sim, quiet: bool = False) -> "StickScaling | TrueInertia":
    """The loading phase's controller: StickScaling (which sets the inertia; ConfigError for a
    wet run above the Deborah bound) when numerics.stick_scaling > 1, else TrueInertia."""
    return StickScaling(config, sim, quiet=quiet) if config.numerics.stick_scaling > 1.0 else TrueInertia()


class StickScaling(Callback):
    """The controller: lambda schedule, rollback to true inertia, guard; checkpointable (its state
    under ``name``). Not scheduled: the series writer calls after_row on every row."""

    name = STICK_SCALING
    changes_step = True      # lambda sets the step: schedules are rebuilt

    def __init__(self, config: Config, sim, quiet: bool = False):
        n = config.numerics
        self.config = config
        self.target = float(n.stick_scaling)
        self.dt_true = sim.scene.dt          # the true step [t0] (config is sim.config)
        self.quiet = quiet
        p = config.packing
        self.d_mean = 0.5 * (p.diameter_min + p.diameter_max)
        self.hi = config.slips.start_factor * config.loading.velocity
        self.lo = config.slips.end_factor * config.loading.velocity
        self.lead = lead_time(config)
        self.quiet_floor = quiet_floor(config)
        self.drop = 0.25 * config.slips.lead_stress
        self.sim = sim
        if sim.fluid is not None and self.target > 1.0:
            self._check_wet(sim)
        self.load_state_dict({})          # (the initial state: lambda = target)

    def load_state_dict(self, state: dict, attached: dict | None = None):
        """The controller's saved state; sets the inertia of its lambda."""
        sim = self.sim
        st = dict(state)
        self.lam = float(st.get("lam", self.target))
        self.onset_scaled = st.get("onset_scaled")      # time of the scaled onset being recomputed
        self.triggered = bool(st.get("triggered", False))
        self.quiet_since = st.get("quiet_since")        # start (t, x_wall) of the quiet window
        self.quiet_x = st.get("quiet_x")
        self.missed_now = bool(st.get("missed_now", False))
        self.slip_span = float(st.get("slip_span", 0.0))    # D: duration of the slip closed in this stretch
        self.peak_tau = float(st.get("peak_tau", -math.inf))        # tau/sigma peak of this stretch
        self.resumed_at = float(st.get("resumed_at", -math.inf))    # when scaling last resumed [t0]
        self.counts = {k: int(st.get(k, 0)) for k in
                       ("rollbacks", "misses", "in_place", "lowered", "steps_scaled", "steps_true",
                        "steps_discarded")}
        self.counted_to = sim.state.step     # steps up to here are in counts (tally)
        set_inertia(sim, self.lam, self.dt_true)

    def sync(self, sim):
        """Before its state is saved: the steps since the last tally counted."""
        self.tally(sim)

    # ---- state ---------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {"lam": self.lam, "onset_scaled": self.onset_scaled, "triggered": self.triggered,
                "quiet_since": self.quiet_since, "quiet_x": self.quiet_x, "missed_now": self.missed_now,
                "slip_span": self.slip_span, "peak_tau": self.peak_tau,
                "resumed_at": self.resumed_at, **self.counts}

    @property
    def scaled(self) -> bool:
        return self.lam > 1.0

    def _check_wet(self, sim):
        g = sim.fluid
        de = stick_deborah_bound(self.config, self.target, g.mean_diffusivity(), 0.5 * g.dz * g.nz)
        bound = self.config.numerics.stick_deborah_max
        if de > bound:
            top = (bound / de) ** 2 * self.target
            raise ConfigError(
                f"numerics.stick_scaling = {self.target:g} in a wet loading run gives a stick-phase Deborah "
                f"number sqrt(lambda) l V_s / D = {de:.3g} above numerics.stick_deborah_max = {bound:g} "
                f"(pressure diffusion does not scale with inertia); use numerics.stick_scaling <= "
                f"{max(top, 1.0):.3g}, or 1")

    # ---- series ---------------------------------------------------------------------------
    def columns(self, sim, row: dict) -> dict:
        """Series columns of this row: lambda, inertial number (and stick Deborah number, wet)."""
        c = self.config
        rate = abs(row["wall_vx"]) / max(row["thickness"], 1e-300)
        out = {"stick_scaling": self.lam,
               "inertial_number": rate * self.d_mean * math.sqrt(self.lam * c.material.density
                                                                 / c.loading.normal_stress)}
        if "deborah" in row:
            out["stick_deborah"] = math.sqrt(self.lam) * row["deborah"]
        return out

    # ---- control --------------------------------------------------------------------------
    def after_row(self, sim, row: dict, recorder: SlipRecorder, slip=None) -> Rollback | None:
        """Called after the recorder saw `row` (`slip`: the slip it closed on this row, if any);
        a Rollback when a scaled stretch ended at an onset (the phase performs it), else None."""
        self.tally(sim)
        t, v = row["time"], row["wall_vx"]
        if self.scaled:
            self.peak_tau = max(self.peak_tau, row["tau_over_sigma"])
            if v >= max(self.lo, self.hi / math.sqrt(self.lam)) or row["tau_over_sigma"] < self.peak_tau - self.drop:
                return self._rollback(sim, recorder, t)
            if v < self.lo:     # the guard watches the quiet stick phase; onsets are rolled back
                self._guard(sim, row)
            return None
        if self.target <= 1.0:
            return None
        # true-inertia stretch after a rollback (or a lowered-to-1 guard)
        self.peak_tau = max(self.peak_tau, row["tau_over_sigma"])
        if v >= self.hi or row["tau_over_sigma"] < self.peak_tau - self.drop:
            self.triggered = True
        if v >= self.hi:                        # a slip in progress: the quiet window starts after it
            self.quiet_since = None
        if not self.triggered and self.onset_scaled is not None and not self.missed_now \
                and t > self.onset_scaled + self.lead:
            self.missed_now = True
            self.counts["misses"] += 1
            self._say(f"stick scaling: the true-inertia recomputation did not slip by t = {t:.6g} t0 "
                      f"(scaled onset {self.onset_scaled:.6g} t0); it goes on at true inertia")
        if slip is not None:
            self.slip_span = float(slip.duration)
        if self.triggered or self.onset_scaled is None:
            x = row["wall_x"]
            if self.quiet_since is None:
                if abs(v) < self.lo:
                    self.quiet_since, self.quiet_x = t, x
            elif t - self.quiet_since >= quiet_window(self.quiet_floor, self.slip_span, self.lead) \
                    and recorder.closed():
                if abs(v) < self.lo and abs(x - self.quiet_x) / (t - self.quiet_since) < self.lo:
                    self._set(sim, self.target)
                    self.resumed_at = t         # kept in the ring: no later rollback goes back past it
                    recorder.forget_peak()      # else a stale peak (a slow slip) keeps the ring empty
                    recorder.keep(sim, always=True)
                    self.onset_scaled, self.triggered, self.quiet_since, self.missed_now = None, False, None, False
                    self.slip_span = 0.0
                else:
                    self.quiet_since, self.quiet_x = t, x
        return None

    def _guard(self, sim, row: dict):
        cols = self.columns(sim, row)
        bound_i = self.config.numerics.stick_inertial_max
        worst = cols["inertial_number"] / bound_i
        if "stick_deborah" in cols:
            worst = max(worst, cols["stick_deborah"] / self.config.numerics.stick_deborah_max)
        if worst > 1.0:
            lam = self.lam * (0.5 / worst) ** 2
            lam = 1.0 if lam < 2.0 else lam
            self.counts["lowered"] += 1
            if lam == 1.0:      # wait for the next slip and its quiet end, as after a rollback
                self.onset_scaled, self.triggered, self.quiet_since, self.missed_now = row["time"], False, None, True
            self._say(f"stick scaling: I = {cols['inertial_number']:.3g} (bound {bound_i:g}) at t = {row['time']:.6g} "
                      f"t0: lambda lowered from {self.lam:g} to {lam:.3g} until the next slip")
            self._set(sim, lam)

    def _rollback(self, sim, recorder: SlipRecorder, t_onset: float) -> Rollback:
        """The scaled onset at `t_onset` [t0]: the pre-slip state to go back to (never one from
        before scaling last resumed: a true-inertia stretch is not redone), or lambda = 1 in place."""
        ck = recorder.choose_pre_slip(t_onset, not_before=self.resumed_at)
        self.onset_scaled, self.triggered, self.quiet_since, self.missed_now = t_onset, False, None, False
        self.slip_span = 0.0
        if ck is None:
            self.counts["in_place"] += 1
            self.triggered = True
            self._set(sim, 1.0)
            return Rollback(None)
        self.counts["rollbacks"] += 1
        self.counts["steps_discarded"] += sim.state.step - ck.step
        self.peak_tau = -math.inf
        return Rollback(ck)

    def after_rewind(self, sim):
        """After the phase put the rollback's state back: lambda = 1 with the stored state as it is
        (no rescaling: a fork from it computes the same)."""
        self._set(sim, 1.0, rescale=False)

    def _set(self, sim, lam: float, rescale: bool = True):
        """Switch to lambda; `rescale`: velocities times sqrt(old / new), so that the switch
        creates no kinetic energy (grains, spins and the top wall)."""
        if lam > 1.0 and self.lam <= 1.0:
            self.peak_tau = -math.inf
        if rescale and lam != self.lam:
            f = math.sqrt(self.lam / lam)
            s = sim.state
            for arr in (s.vx, s.vz, s.spin):
                arr *= f
            s.wall[L.W_VX] *= f
            s.wall[L.W_VZ] *= f
        self.lam = float(lam)
        set_inertia(sim, self.lam, self.dt_true)
        self.counted_to = sim.state.step

    def _say(self, line: str):
        if not self.quiet:
            print(line, file=sys.stderr, flush=True)

    # ---- counts ---------------------------------------------------------------------------
    def finish(self, sim, writer):
        """At the phase's end: the steps counted, the counts into the run file's attribute
        stick_scaling_counts (JSON), the summary on stderr."""
        self.tally(sim)
        writer.set_attr("stick_scaling_counts", json.dumps(self.state_dict()))
        self._say(self.summary())

    def tally(self, sim):
        """Count the steps since the last tally as scaled or true (lambda changes only in
        after_row, which tallies first; the loop is Simulation.run with rebuilt callbacks)."""
        self.counts["steps_scaled" if self.scaled else "steps_true"] += max(sim.state.step - self.counted_to, 0)
        self.counted_to = sim.state.step

    def summary(self) -> str:
        c = self.counts
        total = max(c["steps_scaled"] + c["steps_true"], 1)
        return (f"stick scaling lambda {self.target:g}: {c['rollbacks']} rollbacks to true inertia, "
                f"{c['misses']} without a slip where the scaled run slipped, {c['in_place']} switched in place, "
                f"{c['lowered']} lowered by the guard; {100.0 * c['steps_true'] / total:.1f} % of the steps at "
                f"true inertia, {c['steps_discarded']} steps discarded")


def cycle_steps(config: Config, lam: float, cycle: float, slip: float) -> tuple[float, float]:
    """(steps at lambda = 1, steps at `lam`) of one loading cycle of `cycle` [t0] with a slip of
    `slip` [t0], by the rules above: per cycle the true-inertia stretch is the rollback lead
    (at least slips.lead, the ring spaced lead/4: 1.25 lead), the slip and the quiet window
    (quiet_window); the rest of the cycle and the discarded scaled stretch (1.25 lead)
    run at dt sqrt(lambda). An estimate for projections (gouge bench); the ladder measures it."""
    dt = choose_dt(config)
    true_t, lead = true_stretch(config, cycle, slip)
    if lam <= 1.0:
        return cycle / dt, cycle / dt
    scaled_t = cycle - true_t + ROLLBACK_LEADS * lead
    return cycle / dt, true_t / dt + scaled_t / (dt * math.sqrt(lam))


def true_stretch(config: Config, cycle: float, slip: float) -> tuple[float, float]:
    """(true-inertia time per cycle [t0], slips.lead [t0]): 1.25 lead + slip + quiet window,
    at most the cycle. cycle / true time is the structural cap on the step ratio (lambda -> inf
    still computes that stretch at true inertia and the discarded 1.25 lead at dt sqrt(lambda))."""
    lead = lead_time(config)
    return min(cycle, ROLLBACK_LEADS * lead + slip + quiet_window(quiet_floor(config), slip, lead)), lead
