"""Undrained mean-pressure budget of a sheared wet layer (diagnostic; tests/kernels/test_fluid_walls.py).

A 300-grain layer slides 10 d dry under a stiff spring, then runs wet (kappa_c 1e-9 d^2, P = 0 at
the start) after a x30 velocity step. Every fluid update is recorded (grain state and planes) and
replayed on a fresh grid, which reproduces the run's pressure to round-off, while the mean
pressure is split into the terms of the source

    P* - P^n = (1 + beta P^n) (s_e - s^n) / (beta s^n (1 - s_e)),  s_e = s^{n+1} + dt u_rel . grad s

(the Eulerian change of s; u_x grad_x s; u_z grad_z s, the mirror-extended deposit's gradient since
coupling revision 2), the diffusion with the P = 0 walls, the omitted advection of P, the clamped cells, and the
fluid mass sum((1 + beta P) phi dV), which no undrained motion may change (revision 1 lost 67 % of the pore area made here:
docs/physics/fluid.md, "The wall planes"). Usage: PYTHONPATH=. NUMBA_NUM_THREADS=1 python scripts/fluid_wall_budget.py [updates]
(about a minute after compilation for 1200 updates).
"""

from __future__ import annotations

import sys

import numpy as np

from gouge_cli.config import build_config
from gouge_cli.driver.phases import guarded_run
from gouge_cli.driver.simulation import Simulation
from gouge_cli.kernels import fluid_update as KF
from gouge_cli.kernels import layout as L
from gouge_cli.model.fluid import FluidGrid
from gouge_cli.studies import dilatancy as D

SCENE = {"name": "t", "seed": 5, "packing": {"n_grains": 300, "width": 15},
         "loading": {"velocity": 4e-4}, "numerics": {"dt_safety": 0.3, "threads": 1}}
BETA = 36.0


def record(updates):
    cfg = D.scene(build_config(SCENE), 5, 3e-4, D.STIFF)
    dry = Simulation(cfg)
    guarded_run(dry, 10.0 / 4e-4)
    wet = Simulation(D.wet(cfg, 1e-9), arrays=dry.state.arrays())
    wet.set_loading_velocity(30 * 4e-4)
    every = wet.fluid_interval
    rest = (every - int(wet.state.counters[L.K_STEP]) % every) % every
    if rest:
        wet.advance(rest)
    s, f = wet.state, wet.fluid
    start = (f.pressure.copy(), f.solid_fraction.copy(), f.state.copy(), *wet.wall_planes())
    frames = []
    for _ in range(updates):
        wet.advance(every)
        frames.append((s.x.copy(), s.z.copy(), s.vx.copy(), s.vz.copy(), *wet.wall_planes(), f.pressure.copy()))
    return wet.config, s.radius.copy(), s.width, every * wet.dt, start, frames


def replay(config, radius, width, dt, start, frames):
    P0, s0, state0, zb0, zt0 = start
    grid = FluidGrid.from_config(config.fluid, width, zb0, zt0, radius.size)
    grid.restore({"pressure": P0, "solid_fraction": s0, "state": state0,
                  "drag_x": np.zeros(radius.size), "drag_z": np.zeros(radius.size)})
    f, nz, N = grid.record(), grid.nz, grid.nx * grid.nz
    phi0 = grid.porosity.mean()
    mass0 = ((1 + BETA * grid.pressure) * grid.porosity).sum() * grid.dx * grid.dz
    pore0 = grid.porosity.sum() * grid.dx * grid.dz
    terms = dict.fromkeys(("source", "eulerian", "ux_gx", "uz_gz", "diffusion", "advection"), 0.0)
    clamped, drift, prev = 0, 0.0, (zb0, zt0)
    for n, (x, z, vx, vz, zb, zt, recorded) in enumerate(frames):
        Pn = grid.pressure.copy()
        assert KF.fluid_begin(x, z, vx, vz, radius, x.size, width, zb, zt, dt, f, None, True, True) == 0
        KF.grid_stages(KF.TAPS, KF.SOURCE, width, zb, zt, 0.0, f)
        status = KF.pressure_stage(width, zb, zt, dt, f)
        KF.grid_stages(KF.BACK_Z, KF.N_STAGES, width, zb, zt, dt, f)
        assert status == 0
        drift = max(drift, float(np.abs(grid.pressure - recorded).max()))
        s, so = grid.solid_fraction, grid.previous_solid_fraction
        w = ((zb - prev[0]) + (np.arange(nz) + 0.5) / nz * ((zt - prev[1]) - (zb - prev[0]))) / dt
        prev = (zb, zt)
        uz = grid.solid_velocity_z - w            # (the drag stage stored the absolute uz)
        ux = grid.solid_velocity_x
        c = (1 + BETA * Pn) / (BETA * so * (1 - s)) / N
        terms["source"] += (grid.work[L.G_RHS] - Pn).sum() / N
        terms["diffusion"] += (grid.pressure - grid.work[L.G_RHS]).sum() / N
        terms["eulerian"] += (c * (s - so)).sum()
        terms["ux_gx"] += (c * dt * ux * grid.work[L.G_SX]).sum()
        terms["uz_gz"] += (c * dt * uz * grid.work[L.G_SZ]).sum()
        padded = np.concatenate([np.zeros((grid.nx, 1)), Pn, np.zeros((grid.nx, 1))], axis=1)
        dpz = (padded[:, 2:] - padded[:, :-2]) / (2 * grid.dz)
        dpx = (np.roll(Pn, -1, 0) - np.roll(Pn, 1, 0)) / (2 * grid.dx)
        terms["advection"] += -dt * (ux * dpx + uz * dpz).sum() / N
        clamped += int(((s < 0.1) | (s > 0.95)).sum())
        if (n + 1) % 150 == 0 or n + 1 == len(frames):
            phi = grid.porosity.mean()
            eps = (phi - phi0) / (1 - phi0)
            predicted = (phi0 / (phi0 + eps) - 1) / BETA
            area = grid.dx * grid.dz
            mass = ((1 + BETA * grid.pressure) * grid.porosity).sum() * area
            pore = grid.porosity.sum() * area
            print(f"t {(n + 1) * dt:5.0f}: phi {phi:.4f} mean P {grid.pressure.mean():+.2e} undrained {predicted:+.2e} | "
                  f"source {terms['source']:+.2e} = Eulerian {terms['eulerian']:+.2e} + u_x.g_x {terms['ux_gx']:+.2e} "
                  f"+ u_z.g_z {terms['uz_gz']:+.2e}; diffusion {terms['diffusion']:+.1e}; P advection omitted "
                  f"{terms['advection']:+.1e} | fluid mass lost {(mass - mass0) / (pore - pore0):.0%} of the pore area made")
    print(f"clamped cells {clamped}; replay vs run: max |dP| {drift:.1e}")
    print("mean P per row [1e-4 E]:", np.array2string(grid.pressure.mean(0) * 1e4, precision=1, max_line_width=200))


if __name__ == "__main__":
    run = record(int(sys.argv[1]) if len(sys.argv) > 1 else 1200)
    replay(*run)
