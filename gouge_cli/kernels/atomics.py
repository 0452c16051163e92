"""Atomic integer add for sharing work between the threads of a parallel region (numba offers no
atomics on the CPU): ``fetch_add(counter, i, v)`` adds v to counter[i] in one indivisible step and
returns the value before, so threads that take chunks of a range by ``fetch_add(counter, i, 1)``
each take a different chunk. Which thread takes which chunk varies from run to run: use it only
where each chunk's work is independent of the others and of who does it (kernels.coupled)."""

from numba.core import types
from numba.extending import intrinsic


@intrinsic
def fetch_add(typingctx, counter, index, value):
    """counter[index] += value atomically (sequentially consistent); returns the old value.
    counter : int64[:] C-contiguous; index, value : int64. The index is not checked."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64 and counter.layout == "C"):
        raise TypeError("fetch_add: a C-contiguous int64 array")
    if index != types.int64 or value != types.int64:
        raise TypeError("fetch_add: int64 index and value")

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.atomic_rmw("add", builder.gep(data, [args[1]]), args[2], "seq_cst")
    return types.int64(counter, index, value), codegen

