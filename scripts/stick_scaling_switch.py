"""The switch back to true inertia, far from any slip (README "Stick-phase inertia scaling", 16-seed ladder).

    .venv/bin/python scripts/stick_scaling_switch.py CONFIG [--seed 1] [--lam 256] [--window 2000] [--stage 300]

The scene (stick scaling off) is compacted and loaded at true inertia for 1.6e5 t0, then every
1.5e4 t0 (12 times) the state S is taken where the wall is quiet (|v_wall| < end_factor V_s).
From S the next `window` t0 are run at lambda (velocities times sqrt(1/lambda), as when scaling
resumes) and the run goes back to lambda = 1:

* as_is: velocities as they are (as a rollback restores a ring state of a scaled stretch);
* energy: velocities times sqrt(lambda) (the kinetic energy kept, as the controller's in-place switches);
* ramp: lambda / 4, / 16, ... each for `stage` t0 (velocities as they are), then 1;
* damped: as_is, with the dashpot rate kept at material.damping in the scaled window (force per
  velocity x lambda, damping ratio x sqrt(lambda); damped4: four times that rate);
* grains: as_is, with the top wall at its true mass (only the grains scaled);
* wall: only the top wall's mass scaled (grains and step at true inertia; the grains' velocities
  are still divided by sqrt(lambda) at the start, as in every mode);
* control: lambda = 1 throughout, the same time.

`--modes` picks some (control is always run last).

Printed per mode: the largest wall speed [V_s] in the 200 t0 after the switch back, and when
tau/sigma peaks in them [t0] (200 or so: still rising; 0: falling from the switch on). The
loading run goes on from S at lambda = 1 (the control's state), so the 12 states are those of
one true-inertia run.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from gouge_cli.config import build_config, load_config
from gouge_cli.driver.simulation import Simulation
from gouge_cli.driver.stick_scaling import set_inertia
from gouge_cli.kernels import layout as L
from gouge_cli.model.timestep import choose_dt

MODES = ("as_is", "energy", "ramp", "damped", "damped4", "grains", "wall", "control")


def _scale_velocities(sim, f: float):
    s = sim.state
    for arr in (s.vx, s.vz, s.spin):
        arr *= f
    s.wall[L.W_VX] *= f
    s.wall[L.W_VZ] *= f


def _watch(sim, duration: float, V: float) -> tuple[float, float]:
    """Run `duration` t0 in 10 t0 rows: (largest v_wall / V_s, time of the largest tau/sigma [t0])."""
    vmax, taus = 0.0, []
    for _ in range(int(round(duration / 10.0))):
        sim.run(10.0)
        vmax = max(vmax, sim.observe()["wall_vx"] / V)
        taus.append(sim.tau_over_sigma())
    return vmax, 10.0 * (int(np.argmax(taus)) + 1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", type=Path)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--lam", type=float, default=256.0)
    ap.add_argument("--window", type=float, default=2000.0)
    ap.add_argument("--stage", type=float, default=300.0)
    ap.add_argument("--modes", default="as_is,energy,ramp", help="comma-separated, from " + ", ".join(MODES[:-1]))
    a = ap.parse_args()
    modes = [m for m in a.modes.split(",") if m != "control"] + ["control"]
    if not set(modes) <= set(MODES):
        ap.error(f"--modes: unknown {sorted(set(modes) - set(MODES))}; choose from {', '.join(MODES)}")
    base = load_config(a.config, [])
    cfg = build_config(base.to_dict(), {"seed": a.seed, "numerics.threads": 1, "numerics.stick_scaling": 1.0})
    V, lo = cfg.loading.velocity, cfg.slips.end_factor * cfg.loading.velocity
    sim = Simulation(cfg)
    sim.compact()
    dt1 = choose_dt(cfg)
    sim.run(1.6e5)
    res = {m: [] for m in modes}
    for _ in range(12):
        sim.run(1.5e4)
        if abs(sim.observe()["wall_vx"]) >= lo:
            continue
        start = sim.state.arrays()
        for mode in modes:                          # control last: the run goes on from it
            sim.state.restore(start)
            set_inertia(sim, 1.0, dt1)
            true_params = sim.params.copy()
            if mode != "control":
                _scale_velocities(sim, 1.0 / math.sqrt(a.lam))
                set_inertia(sim, a.lam, dt1)
                if mode in ("damped", "damped4"):
                    sim.params[L.DAMPING] = true_params[L.DAMPING] * (4.0 if mode == "damped4" else 1.0)
                elif mode == "grains":
                    sim.params[L.WALL_MASS] = true_params[L.WALL_MASS]
                elif mode == "wall":
                    scaled_wall = sim.params[L.WALL_MASS]
                    set_inertia(sim, 1.0, dt1)
                    sim.params[L.WALL_MASS] = scaled_wall
                _watch(sim, a.window, V)
                if mode == "energy":
                    _scale_velocities(sim, math.sqrt(a.lam))
                lam = a.lam / 4.0
                while mode == "ramp" and lam > 1.0:
                    set_inertia(sim, lam, dt1)
                    _watch(sim, a.stage, V)
                    lam /= 4.0
                set_inertia(sim, 1.0, dt1)
            else:
                _watch(sim, a.window, V)
            res[mode].append(_watch(sim, 200.0, V))
    for mode in modes:
        r = np.array(res[mode])
        print(f"{mode}: {len(r)} states; largest wall speed in the 200 t0 after the switch: median {np.median(r[:, 0]):.1f} "
              f"V_s ({', '.join(f'{v:.1f}' for v in r[:, 0])}); tau peak after median {np.median(r[:, 1]):.0f} t0")


if __name__ == "__main__":
    main()
