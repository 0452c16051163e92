"""Cell list + Verlet list against brute force over all pairs (kernels.neighbors, kernels.step).

* the list holds exactly the pairs closer than R_i + R_j + skin (periodic x, same-wall pairs
  excluded), for narrow and wide boxes;
* per-grain forces, torques and the top-wall force from the engine equal a numpy all-pairs
  evaluation of the contact law (physics.md section 2) on a compacted packing with walls;
* the tangential history of a pair survives a rebuild, new pairs start at 0.
"""

from __future__ import annotations

import numpy as np
import pytest

from gouge_cli.config import build_config
from gouge_cli.kernels import layout as L
from gouge_cli.kernels import step as K
from gouge_cli.driver.compaction import compact
from gouge_cli.driver.simulation import Simulation


def listed_pairs(st):
    """{(i, j): slot} of the engine's half list (i < j)."""
    out = {}
    for i in range(st.n):
        for k in range(st.start[i], st.start[i + 1]):
            out[(i, int(st.index[k]))] = k
    return out


def all_pairs(st, width):
    i, j = np.triu_indices(st.n, 1)
    dx = st.x[j] - st.x[i]
    dx = np.where(dx > 0.5 * width, dx - width, np.where(dx < -0.5 * width, dx + width, dx))
    dz = st.z[j] - st.z[i]
    interacting = ~((st.body[i] == st.body[j]) & (st.body[i] != 0))
    return i, j, dx, dz, interacting


def brute_force_pairs(st, width, skin):
    i, j, dx, dz, interacting = all_pairs(st, width)
    cut = st.radius[i] + st.radius[j] + skin
    near = (dx * dx + dz * dz < cut * cut) & interacting
    return set(zip(i[near].tolist(), j[near].tolist()))


@pytest.mark.parametrize("width", [3.0, 4.3, 7.3, 50.0])
def test_list_equals_brute_force(free_grains, single_thread, width):
    rng = np.random.default_rng(int(width * 10))
    n = 400
    x = rng.uniform(0.0, width, n)
    x[:3] = [0.0, width * (1 - 1e-16), 0.5 * width]        # edges of the periodic box
    z = rng.uniform(-2.0, 2.0 + 1.5 * n / width, n)
    radius = rng.uniform(0.4, 0.6, n)
    body = rng.choice([0, 0, 1, 2], n)   # free, bottom-wall, top-wall grains mixed: no stepping here
    sim = free_grains(x, z, radius, body=body, width=width)
    st = sim.state
    assert brute_force_pairs(st, width, sim.params[L.SKIN]) == set(listed_pairs(st))


@pytest.fixture(scope="module")
def compacted():
    """A ~600-grain packing with rough walls after (shortened) compaction under sigma."""
    cfg = build_config({"packing": {"n_grains": 600}, "compaction": {"min_time": 500, "max_time": 1500}})
    sim = Simulation(cfg)
    compact(sim)
    return sim


def brute_force_forces(st, params, shear_of):
    """All-pairs numpy evaluation of kernels.hertz_mindlin.force; shear_of(i, j) -> history of the pair."""
    width = params[L.WIDTH]
    i, j, dx, dz, interacting = all_pairs(st, width)
    r = np.sqrt(dx * dx + dz * dz)      # as the kernel: xi = rsum - r amplifies round-off
    rsum = st.radius[i] + st.radius[j]
    touch = (r < rsum) & interacting
    i, j, dx, dz, r, rsum = i[touch], j[touch], dx[touch], dz[touch], r[touch], rsum[touch]
    nx, nz = dx / r, dz / r
    xi = rsum - r
    r_ij = 2 * st.radius[i] * st.radius[j] / rsum
    m_ij = st.mass[i] * st.mass[j] / (st.mass[i] + st.mass[j])
    root = np.sqrt(r_ij * xi)
    dvx, dvz = st.vx[j] - st.vx[i], st.vz[j] - st.vz[i]
    v_n = dvx * nx + dvz * nz
    arm_i, arm_j = st.radius[i] - 0.5 * xi, st.radius[j] - 0.5 * xi     # contact-point lever arms
    v_t = -dvx * nz + dvz * nx - (arm_i * st.spin[i] + arm_j * st.spin[j])
    f_n = np.maximum(params[L.C_NORMAL] * root * xi - params[L.DAMPING] * m_ij * v_n, 0.0)
    k_s = params[L.C_TANGENTIAL] * root
    ds = np.array([shear_of(a, b) for a, b in zip(i, j)]) + v_t * params[L.DT]
    limit = params[L.FRICTION] * f_n
    f_s = np.clip(-k_s * ds, -limit, limit)
    fx, fz = f_n * nx - f_s * nz, f_n * nz + f_s * nx
    n = st.n
    force_x = np.bincount(j, fx, n) - np.bincount(i, fx, n)
    force_z = np.bincount(j, fz, n) - np.bincount(i, fz, n)
    torque = np.bincount(j, -f_s * arm_j, n) + np.bincount(i, -f_s * arm_i, n)
    scale = np.bincount(j, np.hypot(fx, fz), n) + np.bincount(i, np.hypot(fx, fz), n)
    slid = np.abs(k_s * ds) > limit
    return force_x, force_z, torque, scale, set(zip(i.tolist(), j.tolist())), int(slid.sum())


@pytest.mark.parametrize("history", ["zero", "random"])
def test_forces_equal_brute_force(compacted, history):
    sim = compacted
    st, p = sim.state, sim.params
    assert sim.observe()["coordination"] > 2.5      # a dense packing
    pairs = listed_pairs(st)
    rng = np.random.default_rng(7)
    if history == "zero":
        st.shear[:] = 0.0
    else:   # large enough that a good part of the contacts sit on the Coulomb plateau
        st.shear[:] = rng.normal(0.0, 2e-3, st.shear.shape)
    shear = st.shear.copy()
    K.compute_forces(st.grains(), st.lists(), st.pairs(), st.wall, p, *sim.drag)
    fx, fz, torque, scale, touching, n_slid = brute_force_forces(
        st, p, lambda a, b: shear[pairs[(a, b)]])
    assert touching <= set(pairs)                   # the Verlet list missed no contact
    assert len(touching) > st.n
    if history == "random":
        assert n_slid > 0.2 * len(touching)
    tol = 1e-12 * scale + 1e-300
    assert np.all(np.abs(st.force_x - fx) <= tol)
    assert np.all(np.abs(st.force_z - fz) <= tol)
    assert np.all(np.abs(st.torque - torque) <= 1e-12 * scale * st.radius + 1e-300)
    assert np.abs(st.force_x).max() > 1e-3 * scale.max()
    top = st.top
    assert st.wall[L.W_FX] == pytest.approx(fx[top].sum(), rel=1e-12, abs=1e-12 * scale[top].sum())
    assert st.wall[L.W_FZ] == pytest.approx(fz[top].sum(), rel=1e-12)
    # Newton's third law over the whole scene
    assert abs(st.force_x.sum()) < 1e-12 * scale.sum()
    assert abs(st.force_z.sum()) < 1e-12 * scale.sum()


def _by_id(values, ident):
    out = np.empty_like(values)
    out[ident] = values
    return out


def test_verlet_list_is_rebuilt_when_a_grain_leaves_its_skin_and_misses_nothing(compacted):
    """Under loading, the list is rebuilt on a step if and only if some grain then lies farther
    than skin/2 from where it was at the last build (so not every step, and never too late); after
    every step each grain is within skin/2 of its build position and every pair in contact is
    listed. How often grains move that far depends on the trajectory, so every 50th step one grain's
    build position is put just over skin/2 from it, as if it had moved there: the rebuild branch runs
    for every seed."""
    sim = compacted
    st = sim.state
    reach, width = 0.5 * sim.params[L.SKIN], sim.params[L.WIDTH]
    free = np.flatnonzero(st.body == 0)
    planted = rebuilds = 0
    for step in range(300):
        if step % 50 == 25:
            i = free[(7 * step) % free.size]
            st.x_build[i] = (st.x[i] - 1.01 * reach) % width
            planted += 1
        x_build, z_build = _by_id(st.x_build, st.id), _by_id(st.z_build, st.id)
        before = int(st.counters[L.K_REBUILDS])
        sim.advance(1)
        rebuilt = int(st.counters[L.K_REBUILDS]) - before
        dx = _by_id(st.x, st.id) - x_build
        dx -= width * np.round(dx / width)
        far = np.hypot(dx, _by_id(st.z, st.id) - z_build).max()
        assert rebuilt in (0, 1)
        if abs(far - reach) > 1e-12 * reach:            # (a tie within round-off may go either way)
            assert bool(rebuilt) == (far > reach), (step, far, reach, rebuilt)
        rebuilds += rebuilt
        dx = st.x - st.x_build
        dx -= width * np.round(dx / width)
        assert np.hypot(dx, st.z - st.z_build).max() <= reach
        i, j, dx, dz, interacting = all_pairs(st, width)
        touching = (np.hypot(dx, dz) < st.radius[i] + st.radius[j]) & interacting
        assert set(zip(i[touching].tolist(), j[touching].tolist())) <= set(listed_pairs(st)), step
    assert planted <= rebuilds < 300


def test_forces_bitwise_for_any_block_count(compacted):
    """The force pass split into 1..16 parts (what threads run) gives the same bits: every pair's
    law is evaluated alone and every grain sums its pairs in one fixed order."""
    sim = compacted
    st, p = sim.state, sim.params.copy()
    shear0 = np.random.default_rng(3).normal(0.0, 1e-3, st.shear.shape)
    st.pair_buf = np.zeros((16, L.N_BUF, L.PAIR_BUF))    # a chunk buffer per part (16 > threads here)
    results = []
    for blocks in (1, 2, 3, 7, 16):
        p[L.THREADS] = blocks
        st.shear[:] = shear0
        K.compute_forces(st.grains(), st.lists(), st.pairs(), st.wall, p, *sim.drag)
        results.append([a.copy() for a in (st.force_x, st.force_z, st.torque, st.shear, st.wall)])
    npairs = int(st.start[-1])
    incoming = st.rev_slot[:npairs]
    assert sorted(range(npairs), key=lambda k: (st.index[k], k)) == incoming.tolist()
    assert np.array_equal(np.diff(st.rev_start), np.bincount(st.index[:npairs], minlength=st.n))
    for other in results[1:]:
        for a, b in zip(results[0], other):
            assert a.tobytes() == b.tobytes()


def test_shear_history_survives_rebuild(compacted):
    sim = compacted
    st, p = sim.state, sim.params
    before = listed_pairs(st)
    history = {pair: float(np.sin(7.0 * pair[0] + 3.0 * pair[1])) for pair in before}
    for pair, k in before.items():
        st.shear[k] = history[pair]
    # move some grains so that pairs come and go, then rebuild as advance() would
    rng = np.random.default_rng(3)
    free = np.flatnonzero(st.body == 0)
    moved = rng.choice(free, 40, replace=False)
    st.z[moved] += rng.uniform(-0.6, 0.6, moved.size)
    st.x[moved] = (st.x[moved] + rng.uniform(-0.6, 0.6, moved.size)) % st.width
    assert K.rebuild(st.grains(), st.lists(), p, st.counters, *sim.drag)
    after = listed_pairs(st)
    assert brute_force_pairs(st, st.width, p[L.SKIN]) == set(after)
    kept = set(before) & set(after)
    new = set(after) - set(before)
    assert len(kept) > 0.9 * len(before) and new and set(before) - set(after)
    for pair in kept:
        assert st.shear[after[pair]] == history[pair]
    for pair in new:
        assert st.shear[after[pair]] == 0.0


def test_renumbering_moves_grains_with_their_pairs_and_history(compacted):
    """kernels.step.renumber (grains re-numbered by position as the layer shears): every grain
    keeps its position, velocity and properties under its original number (id), every listed
    pair keeps its tangential history, the list is still exact, and the forces are unchanged up
    to round-off (the sums run in a new order). Runs last: it re-numbers the shared packing."""
    sim = compacted
    st, p = sim.state, sim.params.copy()
    p[L.SORT_EVERY] = 1
    rng = np.random.default_rng(5)
    st.shear[:st.start[-1]] = rng.normal(0.0, 1e-3, st.start[-1])
    history = {tuple(sorted((int(st.id[i]), int(st.id[j])))): st.shear[k] for (i, j), k in listed_pairs(st).items()}
    shear = st.shear.copy()
    K.compute_forces(st.grains(), st.lists(), st.pairs(), st.wall, p, *sim.drag)
    st.shear[:] = shear                 # (the force pass advanced the history; take it back)
    before = {name: st.by_id(getattr(st, name)).copy()
              for name in ("x", "z", "vx", "radius", "mass", "inv_inertia", "body", "force_x", "force_z", "torque")}
    # scramble the numbering first (as long shear would), so that renumbering has work to do
    K.renumber(st.grains(), st.lists(), *sim.drag, 7.0)          # (strips of a narrower box: another order)
    assert not np.array_equal(st.id, np.arange(st.n))
    st.counters[L.K_REBUILDS] = 0
    assert K.rebuild(st.grains(), st.lists(), p, st.counters, *sim.drag)
    assert sorted(st.id.tolist()) == list(range(st.n))
    np.testing.assert_array_equal(st.top, np.flatnonzero(st.body == L.TOP))
    pairs = listed_pairs(st)
    assert brute_force_pairs(st, st.width, p[L.SKIN]) == set(pairs)
    assert {tuple(sorted((int(st.id[i]), int(st.id[j])))): st.shear[k] for (i, j), k in pairs.items()} == history
    K.compute_forces(st.grains(), st.lists(), st.pairs(), st.wall, p, *sim.drag)
    for name in ("x", "z", "vx", "radius", "mass", "inv_inertia", "body"):
        np.testing.assert_array_equal(st.by_id(getattr(st, name)), before[name], err_msg=name)
    scale = np.abs(before["force_z"]).max()
    for name in ("force_x", "force_z", "torque"):
        np.testing.assert_allclose(st.by_id(getattr(st, name)), before[name], rtol=0, atol=1e-12 * scale,
                                   err_msg=name)
    # neighbours are close in number again: the median |j - i| of the listed pairs is small
    span = [abs(j - i) for (i, j) in pairs]
    assert np.median(span) < 40
