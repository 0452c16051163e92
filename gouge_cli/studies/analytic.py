"""Analytic reference cases, shared by the accuracy study and the tests: free grains without walls
(the tests' `free_grains` fixture), the Hertz head-on collision (Eqs. 8-11), a closed conservative
box (energy drift), Terzaghi consolidation (the pressure equation, Eq. 18) and the rigid block on
a spring (thesis Eq. 3), each with its error against the closed form."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..config import build_config
from ..driver.simulation import Simulation
from ..kernels import block_slider as KB
from ..kernels import layout as L
from ..model.state import State


@dataclass
class AnalyticRow:
    case: str
    parameter: str
    value: float
    wall_seconds: float
    errors: dict


def free_grains(x, z, radius, *, vx=None, vz=None, spin=None, body=None, width=100.0, dt=0.01,
                normal_stress=None, **material) -> Simulation:
    """A Simulation of free grains (body 0 unless given) with no top wall; the tests' fixture
    ``free_grains`` too. x, z, radius, vx, vz, spin: (N,) [d, d/t0, 1/t0]; material keys go to
    config section ``material`` (damping defaults to 0); background (compaction) damping is
    always 0 so the dynamics are Newtonian."""
    material.setdefault("damping", 0.0)
    data = {"numerics": {"dt": dt}, "compaction": {"damping": 0.0}, "material": material}
    if normal_stress is not None:
        data["loading"] = {"normal_stress": normal_stress}
    cfg = build_config(data)
    x = np.asarray(x, float)
    n = x.shape[0]
    st = State(x=x.copy(), z=np.asarray(z, float).copy(), radius=np.asarray(radius, float).copy(),
               body=np.zeros(n) if body is None else np.asarray(body), density=1.0, width=width)
    for name, value in (("vx", vx), ("vz", vz), ("spin", spin)):
        if value is not None:
            getattr(st, name)[:] = value
    return Simulation(cfg, state=st)


def hertz_reference(v: float) -> tuple[float, float]:
    """(contact time, max overlap) of two d = 1 grains meeting at relative speed v (gamma = 0)."""
    from scipy.special import beta

    from ..model.timestep import contact_constants

    k = contact_constants(build_config({}))[0] * math.sqrt(0.5)
    m_star = math.pi / 12.0
    xi_max = (1.25 * m_star * v * v / k) ** 0.4
    return 0.8 * beta(0.4, 0.5) * xi_max / v, xi_max


def head_on(v: float, steps_per_contact: int) -> tuple[float, float]:
    """(contact time, max overlap) of the engine's head-on collision at dt = t_c / steps."""
    t_c, _ = hertz_reference(v)
    dt = t_c / steps_per_contact
    gap = 3.5 * v * dt
    sim = free_grains([10.0, 11.0 + gap], [0.0, 0.0], [0.5, 0.5], vx=[0.5 * v, -0.5 * v], dt=dt)
    st = sim.state
    overlap = [1.0 - (st.x[1] - st.x[0])]
    while not (overlap[-1] < 0.0 and max(overlap) > 0.0) and len(overlap) < 5 * steps_per_contact:
        sim.advance(1)
        overlap.append(1.0 - (st.x[1] - st.x[0]))
    xi = np.array(overlap)
    inside = np.flatnonzero(xi > 0.0)
    a, b = inside[0], inside[-1]
    t_in = (a - 1) + xi[a - 1] / (xi[a - 1] - xi[a])
    t_out = b + xi[b] / (xi[b] - xi[b + 1])
    return (t_out - t_in) * dt, float(xi.max())


def closed_box(seed=3, width=10.0, nx=8, nz=12, spacing=1.25, v_rms=1e-2) -> dict:
    """Free grains between two rows of fixed grains (one body: they never pair), periodic in x,
    random velocities and spins: a closed conservative system (gamma = mu = 0)."""
    rng = np.random.default_rng(seed)
    xs = (np.arange(nx) + 0.5) * width / nx
    gx, gz = np.meshgrid(xs, 1.25 + np.arange(nz) * spacing)
    x_free = gx.ravel() + rng.uniform(-0.02, 0.02, gx.size)
    z_free = gz.ravel()
    r_free = rng.uniform(0.4, 0.6, x_free.size)
    n_wall = int(width)
    x_wall = (np.arange(n_wall) + 0.5) * width / n_wall
    x = np.concatenate([x_wall, x_free, x_wall])
    z = np.concatenate([np.zeros(n_wall), z_free, np.full(n_wall, z_free.max() + 1.25)])
    radius = np.concatenate([np.full(n_wall, 0.5), r_free, np.full(n_wall, 0.5)])
    body = np.concatenate([np.ones(n_wall), np.zeros(x_free.size), np.ones(n_wall)])
    free = body == 0
    velocities = {name: np.where(free, rng.normal(0.0, v_rms, x.size), 0.0) for name in ("vx", "vz", "spin")}
    return dict(x=x, z=z, radius=radius, body=body, velocities=velocities, width=width)


def total_energy(sim: Simulation) -> float:
    """Kinetic + Hertz energy sum 0.4 c_n sqrt(R_ij) xi^2.5 over touching pairs (same-wall excluded)."""
    st = sim.state
    inertia = st.mass * (2.0 * st.radius) ** 2 / 10.0
    kinetic = 0.5 * np.sum(st.mass * (st.vx ** 2 + st.vz ** 2) + inertia * st.spin ** 2)
    i, j = np.triu_indices(st.n, 1)
    dx = st.x[j] - st.x[i]
    dx -= st.width * np.round(dx / st.width)
    xi = st.radius[i] + st.radius[j] - np.hypot(dx, st.z[j] - st.z[i])
    touching = (xi > 0.0) & ~((st.body[i] == st.body[j]) & (st.body[i] > 0))
    r_ij = 2.0 * st.radius[i] * st.radius[j] / (st.radius[i] + st.radius[j])
    return float(kinetic + np.sum(0.4 * sim.params[L.C_NORMAL] * np.sqrt(r_ij[touching]) * xi[touching] ** 2.5))


def energy_drift(dt: float, duration: float = 200.0, sample: float = 0.32) -> tuple[float, float]:
    """(largest |E - E0| / E0, seconds spent stepping) of the closed box (gamma = mu = 0) over
    `duration` [t0]; the energy is evaluated every `sample` t0 (untimed)."""
    box = closed_box()
    sim = free_grains(box["x"], box["z"], box["radius"], **box["velocities"], dt=dt, width=box["width"],
                      body=box["body"], friction=0.0)
    e0 = total_energy(sim)
    worst, seconds = 0.0, 0.0
    per = max(1, int(round(sample / dt)))
    for _ in range(int(round(duration / (per * dt)))):
        t0 = time.perf_counter()
        sim.advance(per)
        seconds += time.perf_counter() - t0
        worst = max(worst, abs(total_energy(sim) - e0))
    return worst / e0, seconds


def terzaghi_error(nz: int, solver: str = "implicit", ratio: float = 0.5, thickness: float = 10.0) -> float:
    """Largest error of mean and mid-plane P/P0 at T = 0.01, 0.05, 0.1, 0.2, 0.5 on a frozen
    uniform packing (phi = 0.15, two discs per lattice site), fluid steps Delta T = ratio / nz^2."""
    from ..model.fluid import FluidGrid

    targets = (0.01, 0.05, 0.1, 0.2, 0.5)
    m = np.arange(1, 8000, 2)

    def mean(T):
        return float(np.sum(8.0 / (m * np.pi) ** 2 * np.exp(-(m * np.pi) ** 2 * T)))

    def mid(T):
        return float(np.sum(4.0 / (m * np.pi) * np.sin(m * np.pi * 0.5) * np.exp(-(m * np.pi) ** 2 * T)))

    nx, h, z_bot = 2, thickness / nz, 1.0
    xs = (np.arange(nx) + 0.5) * h
    zs = z_bot + (np.arange(nz) + 0.5) * h
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    x, z = np.repeat(X.ravel(), 2), np.repeat(Z.ravel(), 2)
    radius = np.full(x.size, h * np.sqrt(0.85 / (2.0 * np.pi)))
    v = np.zeros_like(x)
    grid = FluidGrid(nx, nz, nx * h, z_bot, z_bot + thickness, x.size, 1e-5, 36.0, 1.43e-7, solver=solver)
    grid.init(x, z, v, v, radius, z_bot, z_bot + thickness)
    diffusivity = grid.mean_diffusivity()
    grid.pressure[:] = 1.0e-6
    delta = ratio / nz ** 2
    due = {round(T / delta): T for T in targets}
    worst = 0.0
    for step in range(1, max(due) + 1):
        if grid.update(x, z, v, v, radius, z_bot, z_bot + thickness, delta * thickness ** 2 / diffusivity) != L.STATUS_OK:
            return float("nan")
        if step in due:
            T = due[step]
            profile = grid.pressure[0] / 1.0e-6
            worst = max(worst, abs(profile.mean() - mean(T)),
                        abs(0.5 * (profile[nz // 2 - 1] + profile[nz // 2]) - mid(T)))
    return worst


def block_slider_errors(dt: float, m=1.0, k=1e-2, sigma=1e-2, mu_s=0.6, mu_d=0.5, v_load=1e-5) -> dict:
    """Relative errors of the first slip's duration, slip and peak velocity against the exact
    solution with loading during the slip (see tests/kernels/test_block_slider.py)."""
    from scipy.optimize import brentq

    p = np.zeros(L.N_PARAMS)
    p[L.DT], p[L.WIDTH], p[L.SIGMA], p[L.SPRING], p[L.V_LOAD] = dt, 1.0, sigma, k, v_load
    p[L.WALL_MASS], p[L.DRIVE] = m, 1.0
    wall, clock, out = np.zeros(L.N_WALL), np.zeros(L.N_CLOCK), np.zeros(5)
    t_end = (mu_s * sigma / k) / v_load + 3.0 * math.pi * math.sqrt(m / k)
    if not KB.block_slip(wall, clock, p, mu_s, mu_d, int(t_end / dt), out):
        return {"duration": float("nan"), "slip": float("nan"), "peak_velocity": float("nan")}
    w, a = math.sqrt(k / m), (mu_s - mu_d) * sigma / k

    def speed(th):
        return w * a * math.sin(th) + v_load * (1.0 - math.cos(th))
    end = brentq(speed, math.pi, 1.5 * math.pi, xtol=1e-15)
    peak_th = brentq(lambda th: w * a * math.cos(th) + v_load * math.sin(th), 0.0, math.pi, xtol=1e-15)
    exact = {"duration": end / w, "slip": a * (1.0 - math.cos(end)) + v_load * (end - math.sin(end)) / w,
             "peak_velocity": speed(peak_th)}
    got = {"duration": out[1] - out[0], "slip": out[3] - out[2], "peak_velocity": out[4]}
    return {key: abs(got[key] - exact[key]) / exact[key] for key in exact}


