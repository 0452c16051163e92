"""The rebuild's bookkeeping by the whole thread block: no phase of the GPU step on one thread.

The serial phases of kernels.gpu.dry (thread 0 bins every grain, writes the row offsets,
re-numbers, reverses the list) are here as block-wide versions that give the same lists, row
for row and slot for slot, as the CPU's kernels.neighbors / kernels.reorder / kernels.step:

* ``p_bucket_order``: the stable counting sort (kernels.neighbors.bucket_order): per-bucket
  counts by integer atomics, a block prefix sum, slots claimed by integer atomics, then each
  bucket's few entries sorted by number, which is the stable order whatever the atomics' order;
* ``p_scan``: in-place prefix sums (the row offsets), a chunk per thread;
* ``p_bin_cells``, ``p_spatial_order``, ``p_renumber_list``, ``p_renumber``,
  ``p_reverse_list``: the CPU functions of those names, built on the two above.
Only integers are counted or sorted and floating-point values are only moved, so the bits do
not depend on the thread count or on the order of the atomics. ``sh``: a shared int64 array of
at least blockDim.x + 1 entries, ``shf``: a shared float64 array (3, blockDim.x).

``clock64()``: the SM's cycle counter (PTX %clock64) for the per-phase timers; under the
simulator, nanoseconds of the host clock.
"""

from __future__ import annotations

import time

from numba import config, cuda

from ..layout import L_BUILT, TOP
from .device import d_cell_grid, d_strip_grid

MAX_THREADS = 1024      # threads per block at most (the shared scratch is sized for it)
SHARED_INTS = 1025      # (MAX_THREADS + 1,) int64 block scratch `sh`
SHARED_FLOATS = (3, 1024)   # (3, MAX_THREADS) float64 block scratch `shf`

if config.ENABLE_CUDASIM:
    def clock64():
        """[ns] host clock (the simulator has no cycle counter)."""
        return time.perf_counter_ns()

    def _shared_array_once():
        """numba-cuda's simulator makes a block's shared array on the first thread to ask, with no
        lock: two threads asking at once get two arrays, and the block no longer shares it (seen
        as an intermittent lockstep failure). The same allocation, keyed as the simulator keys
        it (the caller's file and line), under a lock."""
        import sys
        import threading
        import traceback

        from numba.cuda.simulator import kernelapi

        lock = threading.Lock()
        original = kernelapi.FakeCUDAShared.array

        def array(self, shape, dtype, alignment=None):
            if shape == 0 or alignment is not None:
                return original(self, shape, dtype, alignment)
            dtype = numpy_support.as_dtype(dtype) if isinstance(dtype, types.Type) else dtype
            caller = tuple(traceback.extract_stack(sys._getframe())[-2][0:2])
            with lock:
                if caller not in self._allocations:
                    self._allocations[caller] = np.empty(shape, dtype)
                return self._allocations[caller]

        kernelapi.FakeCUDAShared.array = array

    import numpy as np
    from numba.core import types
    from numba.np import numpy_support

    _shared_array_once()
else:
    from llvmlite import ir
    from numba.cuda import types as _types
    from numba.cuda.extending import intrinsic

    @intrinsic
    def clock64(typingctx):
        """[cycles] the SM's 64-bit cycle counter (PTX %clock64)."""
        def codegen(context, builder, signature, args):
            asm = ir.InlineAsm(ir.FunctionType(ir.IntType(64), []), "mov.u64 $0, %clock64;", "=l", side_effect=True)
            return builder.call(asm, [])

        return _types.int64(), codegen


@cuda.jit(device=True)
def _chunk_offsets(t, nt, sh):
    """sh[:nt] (each thread's chunk total) -> the exclusive prefix sums, by thread 0 between two
    barriers; returns this thread's offset."""
    cuda.syncthreads()
    if t == 0:
        run = 0
        for u in range(nt):
            v = sh[u]
            sh[u] = run
            run += v
    cuda.syncthreads()
    return sh[t]


@cuda.jit(device=True)
def p_scan(t, nt, a, lo, hi, sh):
    """a[lo:hi] = its inclusive prefix sums (integers), by the block: each thread sums its
    contiguous chunk, thread 0 offsets the nt chunk totals, each thread then runs its chunk."""
    m = hi - lo
    c0 = lo + t * m // nt
    c1 = lo + (t + 1) * m // nt
    s = 0
    for i in range(c0, c1):
        s += a[i]
    sh[t] = s
    run = _chunk_offsets(t, nt, sh)
    for i in range(c0, c1):
        run += a[i]
        a[i] = run
    cuda.syncthreads()


@cuda.jit(device=True)
def _shift_back(t, nt, count, nbins):
    """count[1:nbins + 1] = count[0:nbins], count[0] = 0, by the block (each thread reads the
    entry before its chunk before anyone writes)."""
    c0 = 1 + t * nbins // nt
    c1 = 1 + (t + 1) * nbins // nt
    edge = count[c0 - 1] if c1 > c0 else 0
    cuda.syncthreads()
    for b in range(c1 - 1, c0, -1):
        count[b] = count[b - 1]
    if c1 > c0:
        count[c0] = edge
    cuda.syncthreads()
    if t == 0:
        count[0] = 0
    cuda.syncthreads()


@cuda.jit(device=True)
def _sort_segment(values, lo, hi, carry):
    """Insertion sort of values[lo:hi] ascending, carry[lo:hi] moved along (carry may be
    values itself, then nothing extra moves). Segments are a few entries long."""
    for a in range(lo + 1, hi):
        v = values[a]
        c = carry[a]
        b = a - 1
        while b >= lo and values[b] > v:
            values[b + 1] = values[b]
            carry[b + 1] = carry[b]
            b -= 1
        values[b + 1] = v
        carry[b + 1] = c


@cuda.jit(device=True)
def p_bucket_order(t, nt, key, n, nbins, count, order, sh):
    """kernels.neighbors.bucket_order of key[:n] by the block: order[:n] the numbers 0..n-1 by
    key, stable; count[b] the first position of bucket b, count[nbins] = n."""
    for b in range(t, nbins + 1, nt):
        count[b] = 0
    cuda.syncthreads()
    for i in range(t, n, nt):
        cuda.atomic.add(count, key[i] + 1, 1)
    cuda.syncthreads()
    p_scan(t, nt, count, 0, nbins + 1, sh)
    for i in range(t, n, nt):
        order[cuda.atomic.add(count, key[i], 1)] = i
    cuda.syncthreads()
    _shift_back(t, nt, count, nbins)
    for b in range(t, nbins, nt):
        _sort_segment(order, count[b], count[b + 1], order)
    cuda.syncthreads()


@cuda.jit(device=True)
def _extent(t, nt, z, radius, shf):
    """(largest radius, lowest z, highest z) over all grains (exact: min and max do not round),
    known to every thread; radius None-like (shape 0) gives 0."""
    n = z.shape[0]
    rmax = 0.0
    zmin = z[0]
    zmax = z[0]
    for i in range(t, n, nt):
        if radius.shape[0] > 0:
            rmax = max(rmax, radius[i])
        zmin = min(zmin, z[i])
        zmax = max(zmax, z[i])
    shf[0, t] = rmax
    shf[1, t] = zmin
    shf[2, t] = zmax
    cuda.syncthreads()
    if t == 0:
        for u in range(1, nt):
            shf[0, 0] = max(shf[0, 0], shf[0, u])
            shf[1, 0] = min(shf[1, 0], shf[1, u])
            shf[2, 0] = max(shf[2, 0], shf[2, u])
    cuda.syncthreads()
    rmax = shf[0, 0]
    zmin = shf[1, 0]
    zmax = shf[2, 0]
    cuda.syncthreads()
    return rmax, zmin, zmax


@cuda.jit(device=True)
def p_bin_cells(t, nt, x, z, radius, width, skin, cell_of, order, count, sh, shf):
    """kernels.neighbors.bin_cells by the block; (ncx, ncz) known to every thread."""
    n = x.shape[0]
    rmax, zmin, zmax = _extent(t, nt, z, radius, shf)
    cell, cw, ncx, ncz = d_cell_grid(rmax, zmin, zmax, width, skin, count.shape[0])
    for i in range(t, n, nt):
        cx = min(int(x[i] / cw), ncx - 1)
        cz = min(int((z[i] - zmin) / cell), ncz - 1)
        cell_of[i] = cz * ncx + cx
    cuda.syncthreads()
    p_bucket_order(t, nt, cell_of, n, ncx * ncz, count, order, sh)
    return ncx, ncz


@cuda.jit(device=True)
def p_spatial_order(t, nt, x, z, width, perm, inverse, count, sh, shf):
    """kernels.reorder.spatial_order by the block."""
    n = x.shape[0]
    _, zmin, zmax = _extent(t, nt, z, z[:0], shf)
    strips, strip_w, rows, height = d_strip_grid(n, width, zmin, zmax, count.shape[0])
    for i in range(t, n, nt):
        s = min(int(x[i] / strip_w), strips - 1)
        inverse[i] = s * rows + min(int((z[i] - zmin) / height), rows - 1)
    cuda.syncthreads()
    p_bucket_order(t, nt, inverse, n, strips * rows, count, perm, sh)
    for k in range(t, n, nt):
        inverse[perm[k]] = k
    cuda.syncthreads()


@cuda.jit(device=True)
def p_renumber_list(t, nt, inverse, start, index, shear, new_start, new_index, new_shear, old_slot, sh):
    """kernels.reorder.renumber_list by the block: rows counted and slots claimed by integer
    atomics, then each row's pairs put back in the order of their old slots (old_slot, int32
    (capacity,), is scratch: the list's reverse, rebuilt after a re-numbering anyway)."""
    n = inverse.shape[0]
    npairs = start[n]
    for i in range(t, n + 1, nt):
        new_start[i] = 0
    cuda.syncthreads()
    for i in range(t, n, nt):
        a = inverse[i]
        for k in range(start[i], start[i + 1]):
            cuda.atomic.add(new_start, min(a, inverse[index[k]]) + 1, 1)
    cuda.syncthreads()
    p_scan(t, nt, new_start, 0, n + 1, sh)
    for i in range(t, n, nt):
        a = inverse[i]
        for k in range(start[i], start[i + 1]):
            b = inverse[index[k]]
            at = cuda.atomic.add(new_start, min(a, b), 1)
            new_index[at] = max(a, b)
            old_slot[at] = k
    cuda.syncthreads()
    _shift_back(t, nt, new_start, n)
    for r in range(t, n, nt):
        _sort_segment(old_slot, new_start[r], new_start[r + 1], new_index)
    cuda.syncthreads()
    for k in range(t, npairs, nt):
        new_shear[k] = shear[old_slot[k]]
    cuda.syncthreads()
    for i in range(t, n + 1, nt):
        start[i] = new_start[i]
    for k in range(t, npairs, nt):
        index[k] = new_index[k]
        shear[k] = new_shear[k]
    cuda.syncthreads()


@cuda.jit(device=True)
def p_permute(t, nt, values, perm, scratch):
    """kernels.reorder.permute by the block: values[:] = values[perm]."""
    n = perm.shape[0]
    for k in range(t, n, nt):
        scratch[k] = values[perm[k]]
    cuda.syncthreads()
    for k in range(t, n, nt):
        values[k] = scratch[k]
    cuda.syncthreads()


@cuda.jit(device=True)
def p_top_list(t, nt, body, top, sh):
    """top[:] = the numbers of the TOP grains in increasing order (a block-wide compaction)."""
    n = body.shape[0]
    c0 = t * n // nt
    c1 = (t + 1) * n // nt
    m = 0
    for i in range(c0, c1):
        if body[i] == TOP:
            m += 1
    sh[t] = m
    m = _chunk_offsets(t, nt, sh)
    for i in range(c0, c1):
        if body[i] == TOP:
            top[m] = i
            m += 1
    cuda.syncthreads()


@cuda.jit(device=True)
def p_renumber(t, nt, g, li, width, sh, shf):
    """kernels.step.renumber by the block (dry: no drag arrays on the GPU)."""
    p_spatial_order(t, nt, g.x, g.z, width, li.order, li.cell_of, li.cell_count, sh, shf)
    p_renumber_list(t, nt, li.cell_of, li.start, li[1], li.shear, li.new_start, li.new_index, li.new_shear,
                    li.rev_slot, sh)
    order = li.order
    p_permute(t, nt, g.x, order, li.new_shear)
    p_permute(t, nt, g.z, order, li.new_shear)
    p_permute(t, nt, g.vx, order, li.new_shear)
    p_permute(t, nt, g.vz, order, li.new_shear)
    p_permute(t, nt, g.spin, order, li.new_shear)
    p_permute(t, nt, g.radius, order, li.new_shear)
    p_permute(t, nt, g.mass, order, li.new_shear)
    p_permute(t, nt, g.inv_mass, order, li.new_shear)
    p_permute(t, nt, g.inv_inertia, order, li.new_shear)
    p_permute(t, nt, g.force_x, order, li.new_shear)
    p_permute(t, nt, g.force_z, order, li.new_shear)
    p_permute(t, nt, g.torque, order, li.new_shear)
    p_permute(t, nt, g.body, order, li.cell_count)
    p_permute(t, nt, g.id, order, li.cell_count)
    p_top_list(t, nt, g.body, g.top, sh)
    if t == 0:
        li.layout[L_BUILT] = -1
    cuda.syncthreads()


@cuda.jit(device=True)
def p_reverse_list(t, nt, start, index, n, rev_start, rev_slot, sh):
    """kernels.forces.reverse_list by the block."""
    p_bucket_order(t, nt, index, start[n], n, rev_start, rev_slot, sh)

