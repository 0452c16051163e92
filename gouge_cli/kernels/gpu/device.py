"""The CPU kernels' functions compiled for the CUDA target: one source, two targets.

``device(f)`` takes the Python function under a kernel (``f.py_func``) and compiles it with
``cuda.jit(device=True)``, its calls to other kernels bound to their device versions. FMA
contraction is turned off for every CUDA compilation of this process (``contract_off``):
numba's CPU code never contracts a * b + c, NVVM does by default; with it off every
operation of the step is one IEEE-rounded +, -, *, / or sqrt on both targets.
"""

from __future__ import annotations

import types

from numba import cuda

from ..contact import pair_constants, pair_force
from ..neighbors import _carry_history, _scan_row, bucket_order, cell_grid, minimum_image
from ..reorder import permute, renumber_list, spatial_order, strip_grid, strip_width
from ..forces import _sum_range, law_scalars, reverse_list
from ..step import (_half_kick, _move_one, _set_wall_grain_velocity, wall_force, wall_kick)


def contract_off():
    """NVVM option fma=0 for every CUDA compilation that does not ask for fastmath (idempotent)."""
    if cuda.simulator_enabled if hasattr(cuda, "simulator_enabled") else _simulated():
        return
    from numba.cuda.cudadrv import nvvm

    if getattr(nvvm.compile_ir, "gouge_fma_off", False):
        return
    original = nvvm.compile_ir

    def compile_ir(llvmir, **options):
        if not options.get("fastmath"):
            options.setdefault("fma", False)
        return original(llvmir, **options)

    compile_ir.gouge_fma_off = True
    nvvm.compile_ir = compile_ir
    # releases whose callers hold their own reference to compile_ir still build a CompilationUnit
    # (fastmath has become fma=True by then, which setdefault keeps)
    unit = getattr(nvvm, "CompilationUnit", None)
    if unit is not None and not getattr(unit.__init__, "gouge_fma_off", False):
        init = unit.__init__

        def unit_init(self, options, *args, **kwargs):
            options = dict(options or {})
            options.setdefault("fma", False)
            init(self, options, *args, **kwargs)

        unit_init.gouge_fma_off = True
        unit.__init__ = unit_init


def _simulated() -> bool:
    from numba import config

    return bool(config.ENABLE_CUDASIM)


def device(kernel, **calls):
    """kernel's Python source as a CUDA device function; `calls`: name -> device function for
    the kernels it calls (their CPU dispatchers are not callable on the device)."""
    py = getattr(kernel, "py_func", kernel)
    scope = dict(py.__globals__)
    scope.update(calls)
    clone = types.FunctionType(py.__code__, scope, py.__name__, py.__defaults__, py.__closure__)
    clone.__doc__ = py.__doc__
    return cuda.jit(device=True)(clone)


contract_off()

# leaves
d_pair_force = device(pair_force)
d_pair_constants = device(pair_constants)
d_minimum_image = device(minimum_image)
d_half_kick = device(_half_kick)
d_bucket_order = device(bucket_order)
d_scan_row = device(_scan_row)
d_carry_history = device(_carry_history)
d_permute = device(permute)
d_renumber_list = device(renumber_list)
d_strip_width = device(strip_width)
d_cell_grid = device(cell_grid)
d_strip_grid = device(strip_grid, strip_width=d_strip_width)
d_wall_force = device(wall_force)
d_wall_kick = device(wall_kick)
d_set_wall_grain_velocity = device(_set_wall_grain_velocity)
d_sum_range = device(_sum_range)
d_law_scalars = device(law_scalars)
# callers
d_move_one = device(_move_one, _half_kick=d_half_kick, minimum_image=d_minimum_image)
d_reverse_list = device(reverse_list, bucket_order=d_bucket_order)
d_spatial_order = device(spatial_order, strip_grid=d_strip_grid, bucket_order=d_bucket_order)


@cuda.jit
def probe_law(inp, consts, out):
    """The pair constants and contact law of pair k = inp[k] (r_i, r_j, m_i, m_j, dx, dz, dvx, dvz,
    spin_i, spin_j, shear) with consts (dt, c_normal, c_tangential, damping, friction): out[k] =
    (R_ij, m_ij, then pair_force's 7 results); one thread per pair (studies.gpu_check.law_probe)."""
    k = cuda.grid(1)
    if k < inp.shape[0]:
        r_ij, m_ij = d_pair_constants(inp[k, 0], inp[k, 1], inp[k, 2], inp[k, 3])
        res = d_pair_force(inp[k, 4], inp[k, 5], inp[k, 6], inp[k, 7], inp[k, 8], inp[k, 9], inp[k, 0], inp[k, 1],
                              r_ij, m_ij, inp[k, 10], consts[0], consts[1], consts[2], consts[3], consts[4])
        out[k, 0] = r_ij
        out[k, 1] = m_ij
        for c in range(7):
            out[k, 2 + c] = res[c]
