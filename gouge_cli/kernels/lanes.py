"""Vector read-modify-write of consecutive float64 array elements, for scatter loops that the
compiler leaves scalar (numba runs no SLP vectoriser): ``add4(a, i, x0, x1, x2, x3)`` is
``a[i + m] += x_m`` for m = 0..3 as one <4 x double> load, add and store. Each lane is the same
IEEE add (and multiply) as the scalar statement, without fast-math flags: the same bits. On an
AVX2 or AVX-512 target that is one ymm operation; a 128-bit target splits it in two.

i is an unsigned index (no wrap-around of negative indices) and a must be C-contiguous with
i + width <= a.size: these kernels do not check."""

from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic


def _lanes(builder, values, width):
    """<width x double> of the given scalars."""
    vty = ir.VectorType(ir.DoubleType(), width)
    vec = ir.Constant(vty, ir.Undefined)
    for m, x in enumerate(values):
        vec = builder.insert_element(vec, x, ir.Constant(ir.IntType(32), m))
    return vec


def _add_into(context, builder, array_type, array, index, vec, width):
    """array[index:index + width] += vec."""
    data = context.make_array(array_type)(context, builder, array).data
    ptr = builder.bitcast(builder.gep(data, [index]), ir.VectorType(ir.DoubleType(), width).as_pointer())
    builder.store(builder.fadd(builder.load(ptr, align=8), vec), ptr, align=8)


def _check(array, index, values):
    if not (isinstance(array, types.Array) and array.dtype == types.float64 and array.layout == "C"):
        raise TypeError("lanes: a C-contiguous float64 array")
    if index != types.uint64:
        raise TypeError("lanes: the index must be uint64")
    if any(v != types.float64 for v in values):
        raise TypeError("lanes: float64 values")


@intrinsic
def add2(typingctx, array, index, x0, x1):
    """array[index + m] += x_m, m = 0, 1."""
    _check(array, index, (x0, x1))

    def codegen(context, builder, signature, args):
        _add_into(context, builder, signature.args[0], args[0], args[1], _lanes(builder, args[2:4], 2), 2)
        return context.get_dummy_value()
    return types.void(array, index, x0, x1), codegen


@intrinsic
def add4(typingctx, array, index, x0, x1, x2, x3):
    """array[index + m] += x_m, m = 0..3."""
    _check(array, index, (x0, x1, x2, x3))

    def codegen(context, builder, signature, args):
        _add_into(context, builder, signature.args[0], args[0], args[1], _lanes(builder, args[2:6], 4), 4)
        return context.get_dummy_value()
    return types.void(array, index, x0, x1, x2, x3), codegen


@intrinsic
def add4_scaled(typingctx, array, index, x0, x1, x2, x3, scale):
    """array[index + m] += x_m * scale, m = 0..3."""
    _check(array, index, (x0, x1, x2, x3, scale))

    def codegen(context, builder, signature, args):
        vec = builder.fmul(_lanes(builder, args[2:6], 4), _lanes(builder, (args[6],) * 4, 4))
        _add_into(context, builder, signature.args[0], args[0], args[1], vec, 4)
        return context.get_dummy_value()
    return types.void(array, index, x0, x1, x2, x3, scale), codegen


@intrinsic
def bilinear_pairs(typingctx, pairs, index0, index1, a00, a10, a01, a11):
    """(x, z) = a00 p[c00] + a10 p[c10] + a01 p[c01] + a11 p[c11], summed in that order, from
    interleaved (x, z) pairs: p[c] = pairs[2c], pairs[2c + 1]; index0 = 2 c00 and index1 = 2 c10,
    with c01 = c00 + 1 and c11 = c10 + 1 (so each is one 4-lane load). x and z share the lanes of
    each multiply and add: the bits of the two scalar sums."""
    _check(pairs, index0, (a00, a10, a01, a11))
    if index1 != types.uint64:
        raise TypeError("lanes: the index must be uint64")
    result = types.UniTuple(types.float64, 2)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        v4 = ir.VectorType(ir.DoubleType(), 4)
        i32 = ir.IntType(32)

        def load(index):
            return builder.load(builder.bitcast(builder.gep(data, [index]), v4.as_pointer()), align=8)

        def half(vec, h):
            return builder.shuffle_vector(vec, vec, ir.Constant(ir.VectorType(i32, 2), [2 * h, 2 * h + 1]))

        left = builder.fmul(_lanes(builder, (args[3], args[3], args[5], args[5]), 4), load(args[1]))   # c00, c01
        right = builder.fmul(_lanes(builder, (args[4], args[4], args[6], args[6]), 4), load(args[2]))  # c10, c11
        total = builder.fadd(builder.fadd(builder.fadd(half(left, 0), half(right, 0)), half(left, 1)), half(right, 1))
        return context.make_tuple(builder, result, [builder.extract_element(total, ir.Constant(i32, m))
                                                    for m in range(2)])
    return result(pairs, index0, index1, a00, a10, a01, a11), codegen
