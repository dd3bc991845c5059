"""An 8-wide slab test in one go: explicit LLVM vector code for Numba.

LLVM does not vectorise an 8-iteration loop on its own (too short a trip count), so the test of
a wide node's eight child boxes is written as a Numba intrinsic over ``<8 x float>`` vectors
(``<8 x double>`` for float64 rays): eight boxes cost about as much as one scalar box test.
"""

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

#: Children per wide node.
WIDTH = 8


@intrinsic
def enter8(typingctx, nodes, row, ox, oy, oz, ix, iy, iz, fx, fy, fz, tmin, tmax, entry):
    """Test a ray against the eight child boxes of wide node ``row``.

    ``nodes[row, 0:48]`` holds the boxes as six runs of eight float32 (lo x, y, z, hi x, y, z);
    ``ix..iz`` are the reciprocal direction for near planes and ``fx..fz`` the padded one for far
    planes, as in ``traverse._ray_setup``.  The same NaN-safe, conservative test as the scalar
    one: a NaN slab distance (0·inf) never narrows the interval.

    Returns
    -------
    int64
        Bit j set when the ray enters child j within [tmin, tmax]; ``entry[0:8]`` receives the
        entry distances (meaningful where the bit is set).
    """
    real = ox
    sig = types.int64(nodes, row, ox, oy, oz, ix, iy, iz, fx, fy, fz, tmin, tmax, entry)

    def codegen(context, builder, signature, args):
        nodes_v, row_v, *ray, entry_v = args
        ox_v, oy_v, oz_v, ix_v, iy_v, iz_v, fx_v, fy_v, fz_v, tmin_v, tmax_v = ray
        table = context.make_array(signature.args[0])(context, builder, nodes_v)
        start = cgutils.get_item_pointer(context, builder, signature.args[0], table,
                                         [row_v, ir.Constant(ir.IntType(64), 0)])
        lanes = ir.VectorType(ir.FloatType(), WIDTH)
        first = builder.bitcast(start, lanes.as_pointer())
        planes = [builder.load(builder.gep(first, [ir.Constant(ir.IntType(64), k)]), align=4)
                  for k in range(6)]
        scalar = context.get_value_type(real)
        vector = ir.VectorType(scalar, WIDTH)
        if real == types.float64:
            planes = [builder.fpext(plane, vector) for plane in planes]

        def splat(value):
            one = builder.insert_element(ir.Constant(vector, ir.Undefined), value,
                                         ir.Constant(ir.IntType(32), 0))
            return builder.shuffle_vector(one, ir.Constant(vector, ir.Undefined),
                                          ir.Constant(ir.VectorType(ir.IntType(32), WIDTH),
                                                      [0] * WIDTH))

        zero = ir.Constant(scalar, 0.0)
        t_near = splat(tmin_v)
        t_far = splat(tmax_v)
        for axis, (o, i, f) in enumerate(((ox_v, ix_v, fx_v), (oy_v, iy_v, fy_v),
                                          (oz_v, iz_v, fz_v))):
            forward = builder.fcmp_ordered(">=", i, zero)
            near = builder.select(forward, planes[axis], planes[axis + 3])
            far = builder.select(forward, planes[axis + 3], planes[axis])
            origin = splat(o)
            t = builder.fmul(builder.fsub(near, origin), splat(i))
            t_near = builder.select(builder.fcmp_ordered(">", t, t_near), t, t_near)
            t = builder.fmul(builder.fsub(far, origin), splat(f))
            t_far = builder.select(builder.fcmp_ordered("<", t, t_far), t, t_far)
        hit = builder.fcmp_ordered("<=", t_near, t_far)
        out = context.make_array(signature.args[13])(context, builder, entry_v)
        builder.store(t_near, builder.bitcast(out.data, vector.as_pointer()), align=4)
        return builder.zext(builder.bitcast(hit, ir.IntType(WIDTH)), ir.IntType(64))

    return sig, codegen


@intrinsic
def lowest_set_bit(typingctx, mask):
    """Index of the lowest set bit of a non-zero int64 (one instruction: tzcnt)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return sig, codegen
