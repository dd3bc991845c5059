"""Vector code for the BVH builder's innermost loop, binning, for Numba.

A primitive record is eight float32 (box lo xyz, hi xyz, index bits, unused), so one 256-bit
load brings the whole record into a register, its three buckets come from one vector of
centroids, and a bucket's box grows by one vector minimum, one vector maximum and a blend of the
two.  LLVM does not find this on its own from the scalar loop, which took 11 ns per primitive
against 5 ns.  The arithmetic is the scalar code's, operation for operation (no fused
multiply-add, no reassociation), so every primitive lands in the same bucket.
"""

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_F32x4 = ir.VectorType(ir.FloatType(), 4)
_F32x8 = ir.VectorType(ir.FloatType(), 8)
_I32 = ir.IntType(32)
_I64 = ir.IntType(64)


def _row_pointer(context, builder, array_type, array, row):
    """Pointer to ``array[row, 0]`` (a C-contiguous 2-D or 3-D array viewed as rows)."""
    table = context.make_array(array_type)(context, builder, array)
    zeros = [ir.Constant(_I64, 0)] * (array_type.ndim - 1)
    return cgutils.get_item_pointer(context, builder, array_type, table, [row] + zeros)


def _lanes(builder, vector, other, picks):
    return builder.shuffle_vector(vector, other, ir.Constant(ir.VectorType(_I32, len(picks)),
                                                             picks))


def _splat4(builder, value):
    one = builder.insert_element(ir.Constant(_F32x4, ir.Undefined), value,
                                 ir.Constant(_I32, 0))
    return _lanes(builder, one, ir.Constant(_F32x4, ir.Undefined), [0, 0, 0, 0])


def _vector_intrinsic(builder, name):
    """The LLVM intrinsic ``name`` of two eight-float32 vectors, declared in the module being
    built (llvmlite's ``declare_intrinsic`` does not name vector overloads)."""
    signature = ir.FunctionType(_F32x8, [_F32x8, _F32x8])
    return cgutils.get_or_insert_function(builder.module, signature, name)


def _grow(builder, pointer, value):
    """``*pointer`` (eight float32) takes the minimum of lanes 0-2 and the maximum of lanes 3-5
    with ``value``; lanes 6-7 are padding.

    ``llvm.minnum`` and ``llvm.maxnum``, not a compare and a select: LLVM turns the store of a
    select between ``value`` and the loaded box into a masked store: a mask register with
    AVX-512, but ``vmaskmovps`` with AVX2 only, which AMD's cores run as microcode.  On an AVX2
    EPYC the binning's masked stores held most of a build's samples, and builds took 2.3-2.8
    times as long as on a Zen 4 with AVX-512 (Open3D's: 1.3-1.7 times); without them,
    stanford-bunny builds in 20-24 ms rather than 37, two threads.  The result is the same: a
    NaN in ``value`` keeps the box's lane (the box starts at infinities and only takes
    numbers, so it is never NaN).
    """
    pointer = builder.bitcast(pointer, _F32x8.as_pointer())
    box = builder.load(pointer, align=4)
    smaller = builder.call(_vector_intrinsic(builder, "llvm.minnum.v8f32"), [value, box])
    larger = builder.call(_vector_intrinsic(builder, "llvm.maxnum.v8f32"), [value, box])
    builder.store(_lanes(builder, smaller, larger, [0, 1, 2, 11, 12, 13, 6, 7]), pointer,
                  align=4)


def _halves(builder, record):
    """A record's centroid, 0.5 * lo + 0.5 * hi per axis, in lanes 0-2 of the result.  The
    record's lanes 6-7 are replaced by zeros first: they hold an index, whose bits read as a
    subnormal float, and arithmetic on subnormals takes a slow microcode path."""
    zero = ir.Constant(_F32x8, [0.0] * 8)
    box = _lanes(builder, record, zero, [0, 1, 2, 3, 4, 5, 8, 8])
    swapped = _lanes(builder, record, zero, [3, 4, 5, 0, 1, 2, 8, 8])
    half = ir.Constant(_F32x8, [0.5] * 8)
    return builder.fadd(builder.fmul(half, box), builder.fmul(half, swapped))


@intrinsic
def bin_record(typingctx, prims, i, cbox, scale, last, counts, boxes):
    """Add record ``prims[i]`` to the buckets of all three axes.

    The bucket on axis a is ``int(min((0.5 * lo + 0.5 * hi - cbox[a]) * scale[a], last))``,
    as ``split._bin_of`` computes it.  ``cbox`` has at least four float32 and ``scale`` four
    (the fourth lane is computed and dropped); ``counts`` is (3, bins) int64 and ``boxes``
    (3, bins, 8) float32 whose lanes 0-5 are a box.
    """
    sig = types.void(prims, i, cbox, scale, last, counts, boxes)

    def codegen(context, builder, signature, args):
        prims_v, i_v, cbox_v, scale_v, last_v, counts_v, boxes_v = args
        record_ptr = _row_pointer(context, builder, signature.args[0], prims_v, i_v)
        record = builder.load(builder.bitcast(record_ptr, _F32x8.as_pointer()), align=4)
        halves = _halves(builder, record)
        centroid = _lanes(builder, halves, halves, [0, 1, 2, 3])
        cmin = builder.load(builder.bitcast(
            context.make_array(signature.args[2])(context, builder, cbox_v).data,
            _F32x4.as_pointer()), align=4)
        scale = builder.load(builder.bitcast(
            context.make_array(signature.args[3])(context, builder, scale_v).data,
            _F32x4.as_pointer()), align=4)
        bucket = builder.fmul(builder.fsub(centroid, cmin), scale)
        top = _splat4(builder, last_v)
        bucket = builder.select(builder.fcmp_ordered("<", bucket, top), bucket, top)
        bucket = builder.fptosi(bucket, ir.VectorType(_I32, 4))

        counts_type = signature.args[5]
        counts_arr = context.make_array(counts_type)(context, builder, counts_v)
        bins = builder.extract_value(counts_arr.shape, 1)
        count_base = builder.bitcast(counts_arr.data, _I64.as_pointer())
        box_base = builder.bitcast(
            context.make_array(signature.args[6])(context, builder, boxes_v).data,
            _F32x8.as_pointer())
        for axis in range(3):
            row = builder.add(builder.mul(ir.Constant(_I64, axis), bins),
                              builder.sext(builder.extract_element(
                                  bucket, ir.Constant(_I32, axis)), _I64))
            count_ptr = builder.gep(count_base, [row])
            builder.store(builder.add(builder.load(count_ptr), ir.Constant(_I64, 1)), count_ptr)
            _grow(builder, builder.gep(box_base, [row]), record)

    return sig, codegen
