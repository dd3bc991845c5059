"""An 8-wide slab test in one go: explicit LLVM vector code for Numba.

LLVM does not vectorise an 8-iteration loop on its own (too short a trip count), so the test of
a wide node's eight child boxes is written as a Numba intrinsic over ``<8 x float>`` vectors,
for rays of either precision: eight boxes cost about as much as one scalar box test.
"""

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.numpy_support import as_dtype

from raycore._target import compiled_features
from raycore.bvh.layout import NODE_WIDTH, WIDTH

#: Bytes of a wide node's row (:mod:`raycore.bvh.layout`): NODE_WIDTH float32 or int32.
NODE_BYTES = NODE_WIDTH * 4


def _row_start(context, builder, array_type, array, row, row_bytes):
    """``array[row, 0]``'s address as an i8*, for rows of ``row_bytes`` bytes (node rows and
    leaf blocks, whose lengths the library fixes and scene files are checked for).

    A constant stride: Numba's indexing multiplies by the row length it reads from the array,
    a multiply and a reload of that length on the way to every node and leaf block.  Constant,
    random rays took 1-3 % less time (one thread, float32, x86-64-v3 and v4 code; fandisk, spot,
    teapot, stanford-bunny), camera rays 1-3 %.
    """
    if array_type.layout != "C" or array_type.ndim != 2:
        raise TypeError(f"rows of a C-contiguous 2-D array, not {array_type}")
    data = context.make_array(array_type)(context, builder, array).data
    int64 = ir.IntType(64)
    row = row if row.type == int64 else builder.sext(row, int64)
    offset = builder.mul(row, ir.Constant(int64, row_bytes))
    return builder.gep(builder.bitcast(data, ir.IntType(8).as_pointer()), [offset],
                       inbounds=True)


def _splat(builder, vector, value):
    """A ``vector`` with ``value`` in every lane."""
    lanes = vector.count
    one = builder.insert_element(ir.Constant(vector, ir.Undefined), value,
                                 ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(one, ir.Constant(vector, ir.Undefined),
                                  ir.Constant(ir.VectorType(ir.IntType(32), lanes), [0] * lanes))


def _avx2_without_avx512():
    """Whether the kernels are compiled for AVX2 without AVX-512 (16 vector registers, no mask
    registers), where some choices and masks are written for the instructions they need."""
    features = compiled_features()
    return "avx2" in features and "avx512vl" not in features


def _components(context, builder, scalar, axes, values):
    """Components ``axes`` (each an integer 0, 1 or 2) of the triple ``values`` (floats of LLVM
    type ``scalar``), without a branch.

    A float has no conditional move: with AVX2, LLVM compiled each three-way choice of one as
    two branches, on a ray's axes, which random rays take at random.  With AVX2 they are
    permuted in a register instead (``vpermps``, whose indices are a vector: a float64 is two of
    its words); read from a vector by a variable index, through memory, they made framed
    camera rays 8-11 % slower.  Elsewhere the choices stay selects (AVX-512's masked moves).
    """
    if not _avx2_without_avx512():
        def pick(k):
            is0 = builder.icmp_signed("==", k, ir.Constant(k.type, 0))
            is1 = builder.icmp_signed("==", k, ir.Constant(k.type, 1))
            return builder.select(is0, values[0], builder.select(is1, values[1], values[2]))
        return [pick(k) for k in axes]
    i32, f32 = ir.IntType(32), ir.FloatType()
    words = scalar.get_abi_size(context.target_data) // 4  # float32 words in a value
    octet = ir.VectorType(f32, 8)
    data = ir.Constant(octet, ir.Undefined)  # value i in words [words * i, words * (i + 1))
    for i, value in enumerate(values):
        parts = builder.bitcast(value, ir.VectorType(f32, words))
        for word in range(words):
            data = builder.insert_element(
                data, builder.extract_element(parts, ir.Constant(i32, word)),
                ir.Constant(i32, words * i + word))
    index = ir.Constant(ir.VectorType(i32, 8), ir.Undefined)  # result j: value axes[j]'s words
    for j, k in enumerate(axes):
        first = builder.mul(builder.trunc(k, i32), ir.Constant(i32, words))
        for word in range(words):
            index = builder.insert_element(index, builder.add(first, ir.Constant(i32, word)),
                                           ir.Constant(i32, words * j + word))
    permute = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(octet, [octet, index.type]), "llvm.x86.avx2.permps")
    moved = builder.call(permute, [data, index])
    results = []
    for j in range(len(axes)):
        parts = ir.Constant(ir.VectorType(f32, words), ir.Undefined)
        for word in range(words):
            parts = builder.insert_element(
                parts, builder.extract_element(moved, ir.Constant(i32, words * j + word)),
                ir.Constant(i32, word))
        results.append(builder.bitcast(parts, scalar))
    return results


def _lane_bits(builder, mask):
    """The lanes set in ``mask`` (an <L x i1> from a comparison of 256-bit float vectors) as the
    low L bits of an int64.

    With AVX2 (no mask registers), by the movmsk instruction of the compared vectors' width,
    written as its intrinsic: from a plain bitcast, LLVM merged two masks that the caller then
    combines (a block's candidates and its lanes to settle exactly) into one 16-bit mask, by
    packing, shuffling and shifting them, seven instructions where two do.  With AVX-512 the
    bitcast is a move from a mask register.
    """
    int64 = ir.IntType(64)
    lanes = mask.type.count
    if not _avx2_without_avx512():
        return builder.zext(builder.bitcast(mask, ir.IntType(lanes)), int64)
    width = 256 // lanes
    integers = builder.sext(mask, ir.VectorType(ir.IntType(width), lanes))
    floats = ir.VectorType(ir.FloatType() if width == 32 else ir.DoubleType(), lanes)
    name = "llvm.x86.avx.movmsk.ps.256" if width == 32 else "llvm.x86.avx.movmsk.pd.256"
    movmsk = cgutils.get_or_insert_function(builder.module,
                                            ir.FunctionType(ir.IntType(32), [floats]), name)
    return builder.zext(builder.call(movmsk, [builder.bitcast(integers, floats)]), int64)


@intrinsic
def enter8(typingctx, nodes, row, ray, tmin, tmax, entry):
    """Test a ray against the eight child boxes of wide node ``row``, in float32.

    ``nodes[row, 0:48]`` holds the boxes as six runs of eight float32 (lo x, y, z, hi x, y, z);
    ``ray`` is ``traverse._box_ray``'s: the origin for near planes and for far planes, the
    reciprocal direction, and the reciprocal padded for far planes, each (x, y, z) in float32.
    ``tmin`` and ``tmax`` are float32 bounds at or outside the ray's.  The same NaN-safe,
    conservative test as the scalar one: a NaN slab distance (0·inf) never narrows the interval.

    Returns
    -------
    int64
        Bit j set when the ray enters child j within [tmin, tmax]; ``entry[0:8]`` (float32 or
        float64) receives the entry distances (meaningful where the bit is set).
    """
    sig = types.int64(nodes, row, ray, tmin, tmax, entry)

    def codegen(context, builder, signature, args):
        nodes_v, row_v, ray_v, tmin_v, tmax_v, entry_v = args
        start = _row_start(context, builder, signature.args[0], nodes_v, row_v, NODE_BYTES)
        vector = ir.VectorType(ir.FloatType(), WIDTH)
        first = builder.bitcast(start, vector.as_pointer())
        values = [builder.extract_value(ray_v, k) for k in range(12)]
        near_origin, far_origin, reciprocal, padded = (values[k:k + 3] for k in range(0, 12, 3))

        def splat(value):
            return _splat(builder, vector, value)

        def plane(index):
            return builder.load(builder.gep(first, [index]), align=4)

        int64 = ir.IntType(64)
        zero = ir.Constant(ir.FloatType(), 0.0)
        t_near = splat(tmin_v)
        t_far = splat(tmax_v)
        for axis in range(3):
            # the near and far planes are chosen by an offset into the row (Embree's nearX),
            # not by a select of vectors, which LLVM emits as a branch
            forward = builder.fcmp_ordered(">=", reciprocal[axis], zero)
            low, high = ir.Constant(int64, axis), ir.Constant(int64, axis + 3)
            near = plane(builder.select(forward, low, high))
            far = plane(builder.select(forward, high, low))
            t = builder.fmul(builder.fsub(near, splat(near_origin[axis])),
                             splat(reciprocal[axis]))
            t_near = builder.select(builder.fcmp_ordered(">", t, t_near), t, t_near)
            t = builder.fmul(builder.fsub(far, splat(far_origin[axis])), splat(padded[axis]))
            t_far = builder.select(builder.fcmp_ordered("<", t, t_far), t, t_far)
        hit = builder.fcmp_ordered("<=", t_near, t_far)
        out = context.make_array(signature.args[5])(context, builder, entry_v)
        stored = ir.VectorType(context.get_value_type(signature.args[5].dtype), WIDTH)
        if stored != vector:
            t_near = builder.fpext(t_near, stored)
        builder.store(t_near, builder.bitcast(out.data, stored.as_pointer()), align=4)
        return builder.zext(builder.bitcast(hit, ir.IntType(WIDTH)), ir.IntType(64))

    return sig, codegen


@intrinsic
def prefetch_row(typingctx, nodes, row):
    """Ask the memory for the four cache lines of wide node ``row`` (256 bytes), ahead of its
    box test (``llvm.prefetch``: a hint, which never faults).

    A node pushed on the stack waits there while its siblings are visited: fetched now, it is
    in the cache when popped.  Random rays over a mesh larger than the cache wait on node loads;
    this made them 3-6 % faster (stanford-bunny, nefertiti; one and two threads), and coherent
    rays, which find their nodes in the cache, no slower.
    """
    return types.void(nodes, row), _prefetch_codegen(NODE_BYTES)


def _prefetch_codegen(row_bytes):
    """Codegen of a prefetch intrinsic ``(table, row)``: ask for the cache lines of row ``row``
    of the 2D array ``table``, whose rows are ``row_bytes`` long."""
    def codegen(context, builder, signature, args):
        table_v, row_v = args
        base = _row_start(context, builder, signature.args[0], table_v, row_v, row_bytes)
        byte = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte, i32, i32, i32]),
            "llvm.prefetch.p0i8")
        for offset in range(0, row_bytes, 64):
            address = builder.gep(base, [ir.Constant(ir.IntType(64), offset)])
            # a read (0), to be kept in every cache level (3), of data (1)
            builder.call(function, [address, ir.Constant(i32, 0), ir.Constant(i32, 3),
                                    ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return codegen


@intrinsic
def node_int(typingctx, refs, row, column):
    """``refs[row, column]`` (an int32, as an int64) of a node table's int32 view, at the
    constant stride of :func:`_row_start`."""
    sig = types.int64(refs, row, column)

    def codegen(context, builder, signature, args):
        refs_v, row_v, column_v = args
        start = _row_start(context, builder, signature.args[0], refs_v, row_v, NODE_BYTES)
        value = builder.gep(builder.bitcast(start, ir.IntType(32).as_pointer()), [column_v],
                            inbounds=True)
        return builder.sext(builder.load(value, align=4), ir.IntType(64))

    return sig, codegen


@intrinsic
def lowest_set_bit(typingctx, mask):
    """Index of the lowest set bit of a non-zero int64 (one instruction: tzcnt)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return sig, codegen


@intrinsic
def nonnegative(typingctx, index):
    """``index`` (an int64 the caller knows is >= 0), with that fact told to LLVM
    (``llvm.assume``).

    Numba wraps a negative index around (``a[-1]`` is the last element) with a shift, a mask
    and an add before every load and store through a signed index that LLVM cannot prove
    non-negative: a traversal's stack slots and node rows, read and written at every node.
    """
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        value = args[0]
        assume = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [ir.IntType(1)]), "llvm.assume")
        builder.call(assume, [builder.icmp_signed(">=", value, ir.Constant(value.type, 0))])
        return value

    return sig, codegen


#: A leaf block holds as many triangles as one 256-bit vector holds coordinates: eight in
#: float32, four in float64 (Embree's Triangle8v and Triangle4v).  Each of the nine vertex
#: coordinates is stored for the block's triangles side by side (a.x[L], a.y[L], a.z[L], b.x[L],
#: ..., c.z[L]), then the triangles' face indices as int32 (:mod:`raycore.bvh.leaves`): ten
#: planes of 32 bytes, 320 bytes in either precision, five cache lines exactly where the blocks
#: start on a line.  Eight float32 lanes cost what four did and halve the blocks a leaf of up to
#: eight needs: random rays 2-8 % faster and camera rays 3-7 % (one thread, float32,
#: stanford-bunny, nefertiti, teapot, suzanne); eight float64 lanes (512 bits) made nefertiti's
#: random rays 5 % slower, and sixteen float32 lanes 7-31 % slower.
VECTOR_BYTES = 32
MAX_LANES = VECTOR_BYTES // 4
#: Planes of a leaf block: nine coordinates, then the face indices.
BLOCK_PLANES = 10
FACE_PLANE = 9
BLOCK_BYTES = BLOCK_PLANES * VECTOR_BYTES


def lanes_for(dtype):
    """Triangles per leaf block in precision ``dtype``."""
    return VECTOR_BYTES // np.dtype(dtype).itemsize


def block_width(dtype):
    """Values per leaf block (a row of a mesh's blocks) in precision ``dtype``."""
    return BLOCK_PLANES * lanes_for(dtype)


@intrinsic
def prefetch_block(typingctx, blocks, block):
    """Ask the memory for the five cache lines of leaf block ``block`` (BLOCK_BYTES bytes, from
    a line: :func:`raycore.bvh.leaves.empty_blocks`), as :func:`prefetch_row` does for a node.

    The traversal asks for a leaf's blocks as soon as its node's test enters the leaf, and tests
    them once the node's other children are pushed: the first load of a block had been the
    traversal's longest wait (a tenth of a random ray's time on stanford-bunny).  Random rays
    3-7 % faster in float32 and 1-9 % in float64 (closest, any hit, count; stanford-bunny and
    nefertiti, one thread), up to 3 % on teapot and suzanne, cameras 0-2 %.
    """
    return types.void(blocks, block), _prefetch_codegen(BLOCK_BYTES)


@intrinsic
def block_face(typingctx, blocks, block, lane):
    """The face index (int32, as an int64) in lane ``lane`` of leaf block ``block``'s face
    plane: the plane holds int32 in either precision, so it is read through its bytes."""
    sig = types.int64(blocks, block, lane)

    def codegen(context, builder, signature, args):
        blocks_v, block_v, lane_v = args
        int64 = ir.IntType(64)
        start = _row_start(context, builder, signature.args[0], blocks_v, block_v, BLOCK_BYTES)
        plane = builder.gep(start, [ir.Constant(int64, FACE_PLANE * VECTOR_BYTES)])
        face = builder.gep(builder.bitcast(plane, ir.IntType(32).as_pointer()), [lane_v])
        return builder.sext(builder.load(face, align=4), int64)

    return sig, codegen


@intrinsic
def block_lanes(typingctx, blocks):
    """Compiled :func:`lanes_for` of leaf blocks ``blocks`` (B, BLOCK_PLANES * L): L, a constant
    of their type, so that slot arithmetic compiles to shifts."""
    lanes = lanes_for(as_dtype(blocks.dtype))

    def codegen(context, builder, signature, args):
        return ir.Constant(ir.IntType(64), lanes)

    return types.int64(blocks), codegen


@intrinsic
def permuted(typingctx, kx, ky, kz, x, y, z):
    """``(x, y, z)`` along axes ``kx``, ``ky``, ``kz`` (each 0, 1 or 2), without a branch
    (:func:`_components`): a ray's direction as the watertight test permutes it
    (:func:`raycore.primitives.triangle.watertight_setup`)."""
    sig = types.UniTuple(x, 3)(kx, ky, kz, x, y, z)

    def codegen(context, builder, signature, args):
        scalar = context.get_value_type(signature.args[3])
        return context.make_tuple(builder, signature.return_type,
                                  _components(context, builder, scalar, args[:3], args[3:]))

    return sig, codegen


@intrinsic
def watertight_block(typingctx, blocks, block, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin, tmax,
                     out):
    """The watertight test (``raycore.primitives.triangle.watertight``) against the L triangles
    of a leaf block at once (:func:`lanes_for`), without branches.

    Every lane repeats the scalar test's operations in the same order (no contraction into
    fused multiply-adds), so a lane's ``t``, ``u``, ``v`` equal the scalar test's bit for bit.
    Lanes holding NaN (padding, degenerate triangles) fail every comparison and never hit.

    Parameters
    ----------
    blocks : ndarray, shape (B, BLOCK_PLANES * L)
        Leaf blocks in the rays' precision.
    block : int
        Row of ``blocks``.
    ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin, tmax
        The ray and its ``watertight_setup`` values.
    out : ndarray, shape (>= 3 * L,)
        Receives t, u and v of the L lanes (``out[0:L]``, ``out[L:2L]``, ``out[2L:3L]``),
        meaningful where the lane's hit bit is set.

    Returns
    -------
    int64
        Bits 0 to L - 1: lanes hit.  Bits L to 2L - 1: lanes where an edge function rounded to
        0, whose sign must be settled exactly by the scalar test (they are not hit bits).
    """
    sig = types.int64(blocks, block, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmin, tmax, out)

    def codegen(context, builder, signature, args):
        blocks_v, block_v, ox_v, oy_v, oz_v, kx_v, ky_v, kz_v, sx_v, sy_v, sz_v, lo_v, hi_v, \
            out_v = args
        scalar = context.get_value_type(signature.args[2])
        lanes = lanes_for(as_dtype(signature.args[0].dtype))
        vector = ir.VectorType(scalar, lanes)
        int64 = ir.IntType(64)
        start = _row_start(context, builder, signature.args[0], blocks_v, block_v, BLOCK_BYTES)
        first = builder.bitcast(start, vector.as_pointer())

        def splat(value):
            return _splat(builder, vector, value)

        # the origin along the ray's axes, splatted (the same for every block of a ray: LLVM
        # permutes it once, outside the loops over blocks, and splats it in each)
        origin_x, origin_y, origin_z = (
            splat(value) for value in _components(context, builder, scalar,
                                                  (kx_v, ky_v, kz_v), (ox_v, oy_v, oz_v)))

        def relative(vertex, k, origin):
            # axis k of a vertex's lanes, less the origin's: the permutation is an offset into
            # the block, so the axes are loaded in the order the ray needs them
            plane = builder.gep(first, [builder.add(ir.Constant(int64, 3 * vertex),
                                                    builder.sext(k, int64))])
            return builder.fsub(builder.load(plane, align=1), origin)

        shear_x, shear_y, scale = splat(sx_v), splat(sy_v), splat(sz_v)
        sheared = []
        for vertex in range(3):
            # translate by the origin, permute so that kz is forward, shear onto +z
            along = relative(vertex, kz_v, origin_z)
            px = builder.fsub(relative(vertex, kx_v, origin_x), builder.fmul(shear_x, along))
            py = builder.fsub(relative(vertex, ky_v, origin_y), builder.fmul(shear_y, along))
            sheared.append((px, py, along))
        (a_x, a_y, a_z), (b_x, b_y, b_z), (c_x, c_y, c_z) = sheared

        def edge(px, py, qx, qy):
            return builder.fsub(builder.fmul(qx, py), builder.fmul(qy, px))

        u_a = edge(b_x, b_y, c_x, c_y)
        v_b = edge(c_x, c_y, a_x, a_y)
        w_c = edge(a_x, a_y, b_x, b_y)
        zero = ir.Constant(vector, [0.0] * lanes)

        def all3(op, x, y, z):
            return builder.and_(builder.and_(builder.fcmp_ordered(op, x, zero),
                                             builder.fcmp_ordered(op, y, zero)),
                                builder.fcmp_ordered(op, z, zero))

        exact = builder.or_(builder.or_(builder.fcmp_ordered("==", u_a, zero),
                                        builder.fcmp_ordered("==", v_b, zero)),
                            builder.fcmp_ordered("==", w_c, zero))
        inside = builder.or_(all3(">=", u_a, v_b, w_c), all3("<=", u_a, v_b, w_c))
        det = builder.fadd(builder.fadd(u_a, v_b), w_c)
        t_det = builder.fadd(
            builder.fadd(builder.fmul(u_a, builder.fmul(scale, a_z)),
                         builder.fmul(v_b, builder.fmul(scale, b_z))),
            builder.fmul(w_c, builder.fmul(scale, c_z)))
        # make det positive (the paper's sign-mask xor)
        flip = builder.fcmp_ordered("<", det, zero)

        def positive(x):
            return builder.select(flip, builder.fneg(x), x)

        det, t_det, v_b, w_c = positive(det), positive(t_det), positive(v_b), positive(w_c)
        lo, hi = splat(lo_v), splat(hi_v)
        in_range = builder.and_(builder.fcmp_ordered(">=", t_det, builder.fmul(lo, det)),
                                builder.fcmp_ordered("<=", t_det, builder.fmul(hi, det)))
        candidate = builder.and_(builder.and_(inside, in_range),
                                 builder.fcmp_ordered("!=", det, zero))
        # lanes to settle exactly are not candidates
        exact_bits = _lane_bits(builder, exact)
        candidate_bits = builder.and_(_lane_bits(builder, candidate), builder.not_(exact_bits))
        # Most blocks hit nothing: the three divisions wait until a lane is a candidate.
        before = builder.basic_block
        with builder.if_then(builder.icmp_unsigned("!=", candidate_bits, ir.Constant(int64, 0)),
                             likely=False):
            t = builder.fdiv(t_det, det)
            # t is not NaN (inf / inf when the edge functions overflow)
            found = builder.and_(candidate_bits,
                                 _lane_bits(builder, builder.fcmp_ordered("==", t, t)))
            # t/det can round one ulp past a bound that the product test accepted: clamp
            t = builder.select(builder.fcmp_ordered("<", t, lo), lo, t)
            t = builder.select(builder.fcmp_ordered(">", t, hi), hi, t)
            result = context.make_array(signature.args[13])(context, builder, out_v)
            store = builder.bitcast(result.data, vector.as_pointer())
            for k, value in enumerate((t, builder.fdiv(v_b, det), builder.fdiv(w_c, det))):
                builder.store(value, builder.gep(store, [ir.Constant(int64, k)]), align=1)
            tested = builder.basic_block
        hit_bits = builder.phi(int64)
        hit_bits.add_incoming(ir.Constant(int64, 0), before)
        hit_bits.add_incoming(found, tested)
        return builder.or_(hit_bits, builder.shl(exact_bits, ir.Constant(int64, lanes)))

    return sig, codegen
