"""The pair pass: contact forces on every grain from the half neighbour list, in a fixed order.

``derive_list`` (at each list change): the reverse list (rev_start, rev_slot), each slot's first
grain (pair_row), the pairs' constants and, per grain, the ordered list of its force terms
(sum_start, sum_end). ``contact_forces`` (each step): the law pass walks the list's slots in chunks
(``law_pass``: copy-in, then the contact law of kernels.contact in one branch-free loop) and
writes each pair's force and its negation as terms; the sum pass (``sum_pass``) adds each grain's
terms in that fixed order, so the sums are the same bits on any thread count and CPU.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import NUMBA_CACHE
from .contact import pair_constants, pair_force
from .layout import (B_DVX, B_DVZ, B_DX, B_DZ, B_WI, B_WJ, C_NORMAL, C_TANGENTIAL, DAMPING, DT, FRICTION, L_BUILT,
                     PAIR_BUF, PARTS_PER_THREAD, PC_MEFF, PC_REFF, PC_RI, PC_RJ, THREADS, WIDTH)
from .neighbors import bucket_order, minimum_image


@njit(cache=NUMBA_CACHE)
def reverse_list(start, index, n, rev_start, rev_slot):
    """The list by second grain: rev_slot[rev_start[g]:rev_start[g + 1]] are the slots k of the
    pairs (i, g), i < g, in increasing k (a stable counting sort of index by value).
    rev_start: (N + 1,) int64; rev_slot: (capacity,) int32."""
    bucket_order(index[:start[n]], n, rev_start, rev_slot)


@njit(cache=NUMBA_CACHE)
def sum_list(start, rev_start, rev_slot, n, half, sum_start, sum_end):
    """The terms of each grain's sums in their one fixed order (_sum_range), as indices e of the
    sum_x, sum_z, sum_t tables (kernels.layout.Pairs; half: their capacity): grain g's are
    sum_end[sum_start[g]:sum_start[g + 1]]: k for the slots k of the pairs (i, g) in increasing k,
    then half + k for the slots of its own row, then 2 half (-0.0) where that makes an odd count
    even. sum_start (N + 1,) int64; sum_end int32 with room for 2 npairs + N entries."""
    m = 0
    for g in range(n):
        sum_start[g] = m
        for r in range(rev_start[g], rev_start[g + 1]):
            sum_end[m] = rev_slot[r]
            m += 1
        for k in range(start[g], start[g + 1]):
            sum_end[m] = half + k
            m += 1
        if (m - sum_start[g]) % 2 != 0:
            sum_end[m] = 2 * half
            m += 1
    sum_start[n] = m


@njit(cache=NUMBA_CACHE)
def list_constants(start, index, radius, mass, const, row):
    """const (N_PAIR_CONST, capacity), rows PC_*: the radii and kernels.contact.pair_constants of
    every listed pair, and row (capacity,) int32: the first grain i of every slot; constant while
    the list and the masses are: set once per change instead of gathered every step."""
    for i in range(radius.shape[0]):
        ri = radius[i]
        mi = mass[i]
        for k in range(start[i], start[i + 1]):
            j = index[k]
            row[k] = i
            const[PC_RI, k] = ri
            const[PC_RJ, k] = radius[j]
            const[PC_REFF, k], const[PC_MEFF, k] = pair_constants(ri, radius[j], mi, mass[j])


@njit(inline="always", cache=NUMBA_CACHE)
def _fill(k0, k1, x, z, vx, vz, spin, row, index, width, buf):
    """Copy the inputs of pair slots k0:k1 into buf[:, k - k0]: one flat loop over the slots, each
    slot's first grain from row (pairs.pair_row). [A loop per list row, as before 2026-12-07, ends
    after a data-dependent 0-6 slots: about one mispredicted branch per row, half this pass's time.]"""
    for k in range(np.uint64(k0), np.uint64(k1)):
        i = np.uint32(row[k])
        j = np.uint32(index[k])
        q = k - np.uint64(k0)
        buf[B_DX, q] = minimum_image(x[j] - x[i], width)
        buf[B_DZ, q] = z[j] - z[i]
        buf[B_DVX, q] = vx[j] - vx[i]
        buf[B_DVZ, q] = vz[j] - vz[i]
        buf[B_WI, q] = spin[i]
        buf[B_WJ, q] = spin[j]


@njit(error_model="numpy", cache=NUMBA_CACHE)
def _laws(m, buf, base, dt, c_n, c_t, damping, friction, shear, const, sum_x, sum_z, sum_t):
    """The contact law (kernels.contact.pair_force) on buf[:, :m] for slots base:base + m (their
    shear history and constants read in place), results to shear and to the terms of the two grains'
    sums [sum_x, sum_z, sum_t at k: fx, fz (force on j), tj; at half + k: -fx, -fz, ti;
    kernels.layout.Pairs] at those slots: a loop without branches or gathers, which LLVM
    vectorises (SIMD lanes do the same IEEE operations as the scalar law: same bits; -f is exact)."""
    half = np.uint64((sum_x.shape[0] - 1) // 2)
    for q in range(m):
        k = np.uint64(base + q)
        fx, fz, ti, tj, ds, overlap, fn = pair_force(
            buf[B_DX, q], buf[B_DZ, q], buf[B_DVX, q], buf[B_DVZ, q], buf[B_WI, q], buf[B_WJ, q],
            const[PC_RI, k], const[PC_RJ, k], const[PC_REFF, k], const[PC_MEFF, k], shear[k], dt, c_n, c_t,
            damping, friction)
        sum_x[k] = fx
        sum_z[k] = fz
        sum_t[k] = tj
        sum_x[half + k] = -fx
        sum_z[half + k] = -fz
        sum_t[half + k] = ti
        shear[k] = ds


@njit(inline="always", cache=NUMBA_CACHE)
def _pair_range(k_lo, k_hi, x, z, vx, vz, spin, row, index, shear, const, sum_x, sum_z, sum_t, buf, width, dt,
                c_n, c_t, damping, friction):
    """The law for list slots k_lo:k_hi, in chunks of PAIR_BUF slots (copy in, SIMD law)."""
    k0 = k_lo
    while k0 < k_hi:
        k1 = min(k0 + PAIR_BUF, k_hi)
        _fill(k0, k1, x, z, vx, vz, spin, row, index, width, buf)
        _laws(k1 - k0, buf, k0, dt, c_n, c_t, damping, friction, shear, const, sum_x, sum_z, sum_t)
        k0 = k1


@njit(inline="always", cache=NUMBA_CACHE)
def _sum_range(g0, g1, start, rev_start, rev_slot, pair_fx, pair_fz, pair_ti, pair_tj, force_x, force_z, torque,
               drag, drag_x, drag_z):
    """Force and torque of grains g0:g1 from the pair results, in the one fixed order: the pairs
    where g is second (+, increasing slot, i.e. increasing i), then its own row (-, in slot
    order), then drag. (The GPU engine's sum, kernels.gpu; the host's pass is _sum_terms, the same
    terms in the same order.)"""
    for g in range(np.uint64(g0), np.uint64(g1)):
        fx = 0.0
        fz = 0.0
        ts = 0.0
        for r in range(rev_start[g], rev_start[g + 1]):
            k = np.uint32(rev_slot[r])
            fx += pair_fx[k]
            fz += pair_fz[k]
            ts += pair_tj[k]
        for k in range(np.uint64(start[g]), np.uint64(start[g + 1])):
            fx -= pair_fx[k]
            fz -= pair_fz[k]
            ts += pair_ti[k]
        if drag:
            fx += drag_x[g]
            fz += drag_z[g]
        force_x[g] = fx
        force_z[g] = fz
        torque[g] = ts


@njit(inline="always", cache=NUMBA_CACHE)
def _sum_terms(g0, g1, sum_start, sum_end, sum_x, sum_z, sum_t, force_x, force_z, torque, drag, drag_x, drag_z):
    """_sum_range's sums: the same terms in the same order (sum_list), without its two loops of
    data-dependent length per grain: one loop, two terms a turn. Same bits: where _sum_range
    subtracts f this adds -f (x + (-f) = x - f exactly), and the padding adds -0.0 (x + (-0.0) = x
    exactly)."""
    for g in range(np.uint64(g0), np.uint64(g1)):
        fx = 0.0
        fz = 0.0
        ts = 0.0
        for c in range(np.uint64(sum_start[g]), np.uint64(sum_start[g + 1]), np.uint64(2)):
            e = np.uint32(sum_end[c])
            f = np.uint32(sum_end[c + np.uint64(1)])
            fx += sum_x[e]
            fz += sum_z[e]
            ts += sum_t[e]
            fx += sum_x[f]
            fz += sum_z[f]
            ts += sum_t[f]
        if drag:
            fx += drag_x[g]
            fz += drag_z[g]
        force_x[g] = fx
        force_z[g] = fz
        torque[g] = ts


@njit(cache=NUMBA_CACHE)
def derive_list(grains, lists, pairs):
    """The arrays the force pass derives from the list and the masses: the reverse list
    (lists.rev_start, rev_slot), the pair constants and rows (pairs.pair_const, pair_row) and the
    sum list (pairs.sum_start, sum_end, and the -0.0 term); marks them current."""
    reverse_list(lists.start, lists.index, grains.x.shape[0], lists.rev_start, lists.rev_slot)
    list_constants(lists.start, lists.index, grains.radius, grains.mass, pairs.pair_const, pairs.pair_row)
    half = (pairs.sum_x.shape[0] - 1) // 2
    pairs.sum_x[2 * half] = -0.0
    pairs.sum_z[2 * half] = -0.0
    pairs.sum_t[2 * half] = -0.0
    sum_list(lists.start, lists.rev_start, lists.rev_slot, grains.x.shape[0], half, pairs.sum_start, pairs.sum_end)
    lists.layout[L_BUILT] = 1


@njit(cache=NUMBA_CACHE)
def force_parts(threads, n, buffers):
    """Parts of each force pass for params[THREADS] = threads: 1 on one thread, else
    PARTS_PER_THREAD per thread, at most n and the number of chunk buffers."""
    t = max(int(threads), 1)
    return min(1 if t == 1 else PARTS_PER_THREAD * t, max(n, 1), buffers)


@njit(cache=NUMBA_CACHE)
def contact_forces(grains, lists, pairs, drag_x, drag_z, params):
    """grains.force_x, force_z, torque (N,) = contact forces of all listed pairs (+ drag_x, drag_z
    (N,) when they have N entries; (0,) for none); lists.shear updated (thesis Eqs. 8-11).
    grains, lists, pairs: kernels.layout.Grains, Lists, Pairs.

    Two passes, each split into nb equal parts, PARTS_PER_THREAD per thread when there are
    several (smaller parts balance the threads better; no part reads what another
    part of the same pass writes): the law of every listed pair (law_pass) into pairs.pair_*,
    then the sum per grain (sum_pass) in the one fixed order of _sum_range. Every pair's result
    and every sum are the same for any nb: same bits on any thread count. The passes are separate
    parallel functions: numba fuses adjacent prange loops of equal range, which would let a part sum
    pairs another part has not yet computed."""
    n = grains.x.shape[0]
    if lists.layout[L_BUILT] < 0:
        derive_list(grains, lists, pairs)
    nb = force_parts(params[THREADS], n, pairs.pair_buf.shape[0])
    law_pass(nb, grains.x, grains.z, grains.vx, grains.vz, grains.spin, lists.start, pairs.pair_row, lists.index,
              lists.shear, pairs.pair_const, pairs.sum_x, pairs.sum_z, pairs.sum_t, pairs.pair_buf, params)
    sum_pass(nb, pairs.sum_start, pairs.sum_end, pairs.sum_x, pairs.sum_z, pairs.sum_t, grains.force_x,
              grains.force_z, grains.torque, drag_x, drag_z)


@njit(inline="always", cache=NUMBA_CACHE)
def law_scalars(params):
    """(dt, width, c_normal, c_tangential, damping, friction): the pair pass's scalars from params
    (the law's last four arguments, kernels.contact)."""
    return params[DT], params[WIDTH], params[C_NORMAL], params[C_TANGENTIAL], params[DAMPING], params[FRICTION]


@njit(parallel=True, error_model="numpy", cache=NUMBA_CACHE)
def law_pass(nb, x, z, vx, vz, spin, start, row, index, shear, const, sum_x, sum_z, sum_t, pair_buf, params):
    """The law of every listed pair, slots in nb equal ranges (_pair_range), chunk buffers
    pair_buf[part] (N_BUF, PAIR_BUF); row: the first grain of each slot (pairs.pair_row). [Arrays,
    not the records: the parallel loops keep the code they were measured with.]"""
    dt, width, c_n, c_t, damping, friction = law_scalars(params)
    npairs = start[x.shape[0]]
    for b in prange(nb):
        _pair_range(b * npairs // nb, (b + 1) * npairs // nb, x, z, vx, vz, spin, row, index, shear, const,
                    sum_x, sum_z, sum_t, pair_buf[b], width, dt, c_n, c_t, damping, friction)


@njit(parallel=True, cache=NUMBA_CACHE)
def sum_pass(nb, sum_start, sum_end, sum_x, sum_z, sum_t, force_x, force_z, torque, drag_x, drag_z):
    """Force and torque of every grain (_sum_terms), grains in nb equal ranges."""
    n = force_x.shape[0]
    has_drag = drag_x.shape[0] == n
    for b in prange(nb):
        _sum_terms(b * n // nb, (b + 1) * n // nb, sum_start, sum_end, sum_x, sum_z, sum_t, force_x, force_z,
                   torque, has_drag, drag_x, drag_z)
