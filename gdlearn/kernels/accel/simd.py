"""Explicit 8-wide SIMD for the BVH leaf test: one LLVM vector instruction per operation.

:mod:`gdlearn.kernels.accel.bvh` tests a leaf's triangles and parallelograms as *lanes* of a block
(structure of arrays). Written as a plain numba loop, the compiler vectorises it -- but how wide
depends on the surrounding code: inlined into the path tracer's bounce loop LLVM chose 4 lanes and
spilled registers (730 instructions per Cornell-box traversal in callgrind, 44% of a path's
instructions), in a small test function 8 lanes. :func:`block8` emits the test for 8 lanes
directly as ``<8 x double>`` LLVM IR (zmm registers with AVX-512; two ymm halves with AVX2, the
same results), so the code is the same wherever it is inlined.

The arithmetic is exactly :func:`bvh._lane_tuv`'s (Moeller-Trumbore), operation for operation, in
IEEE float64 without contraction or reassociation: every lane gives the bits the scalar code gives.
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from gdlearn.kernels.accel.bvh_build import CHILD_MASK, WIDE

W = 8                                      # lanes per block (and children per wide node)
assert WIDE == W
_KEY_HIGH = 0x7FFFFFFFFFFFFF00             # see bvh: distance bits, the sign bit cleared
_NO_HIT = 0x7FFFFFFFFFFFFFFF


def _splat(builder, value, vty):
    """``value`` in every lane of a vector of type ``vty``."""
    v = builder.insert_element(ir.Constant(vty, ir.Undefined), value, ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(v, ir.Constant(vty, ir.Undefined), ir.Constant(ir.VectorType(ir.IntType(32), vty.count),
                                                                              [0] * vty.count))


def _load(builder, base, index, vty):
    """The ``vty.count`` doubles at ``base[index : ...]`` as one vector (unaligned load)."""
    ptr = builder.gep(base, [index])
    return builder.load(builder.bitcast(ptr, vty.as_pointer()), align=8)


def _store(builder, vec, base, index, vty):
    builder.store(vec, builder.bitcast(builder.gep(base, [index]), vty.as_pointer()), align=8)


def _block_codegen(w):
    """The code of :func:`block8` (w = 8) and :func:`block4` (w = 4): the same per-lane operations."""

    def codegen(context, builder, signature, args):
        return _block_ir(w, context, builder, signature, args)

    return codegen


@intrinsic
def block8(typingctx, nodes, i, s, o, d, tmin, tmax, k0, scratch, keep):
    """The smallest nearest-hit key of the 8 lanes ``i .. i+7`` of a block with row stride ``s``
    (``bvh._leaf_lanes``'s keys: distance bits | lane ``k0 + j``, all ones on a miss; hit means
    a, b in [0, 1], a + b <= lim, t > 0, tmin < t < tmax). With ``keep`` the lanes' t, a, b are
    stored at ``scratch[k0 + j]``, ``scratch[64 + k0 + j]``, ``scratch[128 + k0 + j]``."""
    return types.int64(nodes, i, s, o, d, tmin, tmax, k0, scratch, keep), _block_codegen(8)


@intrinsic
def block4(typingctx, nodes, i, s, o, d, tmin, tmax, k0, scratch, keep):
    """:func:`block8` for the first 4 lanes ``i .. i+3`` only (``<4 x double>``: one ymm register):
    a leaf's last block when it holds at most 4 lanes (the close-up's whole scene: 2), at half the
    work of 8. The lanes it tests give the bits and keys :func:`block8` gives them."""
    return types.int64(nodes, i, s, o, d, tmin, tmax, k0, scratch, keep), _block_codegen(4)


def _block_ir(w, context, builder, signature, args):
    """The lane test of ``w`` lanes as ``<w x double>`` IR, returning their smallest key."""
    a_nodes, a_i, a_s, a_o, a_d, a_tmin, a_tmax, a_k0, a_scr, a_keep = args
    f64, i64 = ir.DoubleType(), ir.IntType(64)
    vd, vi = ir.VectorType(f64, w), ir.VectorType(i64, w)
    base = context.make_array(signature.args[0])(context, builder, value=a_nodes).data
    row = [_load(builder, base, builder.add(a_i, builder.mul(a_s, i64(r))), vd) for r in range(10)]
    p0x, p0y, p0z, e1x, e1y, e1z, e2x, e2y, e2z, lim = row
    ox, oy, oz = (_splat(builder, builder.extract_value(a_o, k), vd) for k in range(3))
    dx, dy, dz = (_splat(builder, builder.extract_value(a_d, k), vd) for k in range(3))
    mul, sub, add = builder.fmul, builder.fsub, builder.fadd
    # the scalar code's operations, in its order (bvh._lane_tuv)
    pvx = sub(mul(dy, e2z), mul(dz, e2y))
    pvy = sub(mul(dz, e2x), mul(dx, e2z))
    pvz = sub(mul(dx, e2y), mul(dy, e2x))
    inv = builder.fdiv(ir.Constant(vd, [1.0] * w), add(add(mul(e1x, pvx), mul(e1y, pvy)), mul(e1z, pvz)))
    tx, ty, tz = sub(ox, p0x), sub(oy, p0y), sub(oz, p0z)
    a = mul(add(add(mul(tx, pvx), mul(ty, pvy)), mul(tz, pvz)), inv)
    qx = sub(mul(ty, e1z), mul(tz, e1y))
    qy = sub(mul(tz, e1x), mul(tx, e1z))
    qz = sub(mul(tx, e1y), mul(ty, e1x))
    b = mul(add(add(mul(dx, qx), mul(dy, qy)), mul(dz, qz)), inv)
    t = mul(add(add(mul(e2x, qx), mul(e2y, qy)), mul(e2z, qz)), inv)
    zero, one = ir.Constant(vd, [0.0] * w), ir.Constant(vd, [1.0] * w)
    cmp = builder.fcmp_ordered
    ok = builder.and_(cmp(">=", a, zero), cmp(">=", b, zero))
    ok = builder.and_(ok, builder.and_(cmp("<=", a, one), cmp("<=", b, one)))
    ok = builder.and_(ok, cmp("<=", add(a, b), lim))
    ok = builder.and_(ok, builder.and_(cmp(">", t, zero), cmp(">", t, _splat(builder, a_tmin, vd))))
    ok = builder.and_(ok, cmp("<", t, _splat(builder, a_tmax, vd)))
    lane = builder.add(_splat(builder, a_k0, vi), ir.Constant(vi, list(range(w))))
    key = builder.or_(builder.and_(builder.bitcast(t, vi), ir.Constant(vi, [_KEY_HIGH] * w)), lane)
    key = builder.select(ok, key, ir.Constant(vi, [_NO_HIT] * w))
    with builder.if_then(a_keep):
        sbase = context.make_array(signature.args[8])(context, builder, value=a_scr).data
        _store(builder, t, sbase, a_k0, vd)
        _store(builder, a, sbase, builder.add(a_k0, i64(64)), vd)
        _store(builder, b, sbase, builder.add(a_k0, i64(128)), vd)
    smin = cgutils.get_or_insert_function(builder.module, ir.FunctionType(i64, [vi]),
                                          f"llvm.vector.reduce.smin.v{w}i64")
    return builder.call(smin, [key])


# ------------------------------------------------------------------------------- wide interior nodes
#: an optimal sorting network for 8 keys (Knuth, TAOCP vol. 3, 5.3.4: 19 comparators in 6 layers),
#: each layer's comparators disjoint so that a layer is one min, one max and one blend of vectors
NETWORK8 = (((0, 2), (1, 3), (4, 6), (5, 7)), ((0, 4), (1, 5), (2, 6), (3, 7)),
            ((0, 1), (2, 3), (4, 5), (6, 7)), ((2, 4), (3, 5)), ((1, 4), (3, 6)),
            ((1, 2), (3, 4), (5, 6)))


def _sort_desc(builder, v, vi):
    """The 8 int64 lanes of ``v`` sorted in descending order (:data:`NETWORK8`)."""
    i32 = ir.IntType(32)
    for layer in NETWORK8:
        perm, upper = list(range(W)), [False] * W
        for a, b in layer:
            perm[a], perm[b] = b, a
            upper[a] = True                       # the lower lane of a pair keeps the larger key
        other = builder.shuffle_vector(v, ir.Constant(vi, ir.Undefined), ir.Constant(ir.VectorType(i32, W), perm))
        gt = builder.icmp_signed(">", v, other)
        big, small = builder.select(gt, v, other), builder.select(gt, other, v)
        v = builder.select(ir.Constant(ir.VectorType(ir.IntType(1), W), upper), big, small)
    return v


@intrinsic
def children8(typingctx, nodes, off, o, inv, tmin, tmax, keys, sp):
    """Slab tests of a wide node's 8 children at once: returns (n, nearest, farthest), the number
    of children whose box the ray enters in (tmin, tmax) and the keys of the nearest and the
    farthest of them, and stores all 8 lanes' keys (-1 for a child not entered) at
    ``keys[sp + 1 : sp + 9]`` for :func:`sort8` (``bvh._push_children``: with two children the
    farthest is all there is to push, and no sort is needed; 80 % of the wide nodes of the mesh
    scene's rays enter one or two).

    The node's block at ``nodes[off:]`` is 7 rows of 8 lanes: the children's box minima (x, y, z),
    maxima (x, y, z) and node indices (as float64; -1 for an empty lane). Per lane the arithmetic,
    NaN handling and 2-ulp widening are ``bvh._box_hit``'s. A key is the entry distance's IEEE bits
    with the low ``bvh_build.CHILD_BITS`` replaced by the child's index: integer order is distance
    order, and the distance it keeps is rounded down (a node is never culled by it wrongly)."""
    if not (isinstance(keys, types.Array) and keys.dtype == types.int64):
        return None
    sig = types.UniTuple(types.int64, 3)(nodes, off, o, inv, tmin, tmax, keys, sp)

    def codegen(context, builder, signature, args):
        a_nodes, a_off, a_o, a_inv, a_tmin, a_tmax, a_keys, a_sp = args
        f64, i64 = ir.DoubleType(), ir.IntType(64)
        vd, vi = ir.VectorType(f64, W), ir.VectorType(i64, W)
        base = context.make_array(signature.args[0])(context, builder, value=a_nodes).data
        row = [_load(builder, base, builder.add(a_off, i64(W * r)), vd) for r in range(7)]
        o3 = [_splat(builder, builder.extract_value(a_o, k), vd) for k in range(3)]
        i3 = [_splat(builder, builder.extract_value(a_inv, k), vd) for k in range(3)]
        mul, sub = builder.fmul, builder.fsub
        cmp = builder.fcmp_ordered

        def fmin(a, b):                     # bvh._fmin: b if b < a else a (a NaN in b is ignored)
            return builder.select(cmp("<", b, a), b, a)

        def fmax(a, b):
            return builder.select(cmp(">", b, a), b, a)

        t0 = [mul(sub(row[k], o3[k]), i3[k]) for k in range(3)]
        t1 = [mul(sub(row[3 + k], o3[k]), i3[k]) for k in range(3)]
        lo = fmax(fmax(fmin(t0[0], t1[0]), fmin(t0[1], t1[1])), fmax(fmin(t0[2], t1[2]), _splat(builder, a_tmin, vd)))
        hi = fmin(fmin(fmax(t0[0], t1[0]), fmax(t0[1], t1[1])), fmin(fmax(t0[2], t1[2]), _splat(builder, a_tmax, vd)))
        hi = mul(hi, ir.Constant(vd, [1.0000000000000004] * W))
        zero = ir.Constant(vd, [0.0] * W)
        ok = builder.and_(cmp("<=", lo, hi), cmp(">=", row[6], zero))
        # keys of hits >= 0: -0 and the negative entries a NaN slab lets through (an origin on a
        # slab of an axis-parallel ray) count as 0
        lo = builder.select(cmp(">", lo, zero), lo, zero)
        key = builder.and_(builder.bitcast(lo, vi), ir.Constant(vi, [~CHILD_MASK] * W))
        key = builder.or_(key, builder.fptosi(row[6], vi))
        kbase = context.make_array(signature.args[6])(context, builder, value=a_keys).data
        entered = builder.select(ok, key, ir.Constant(vi, [-1] * W))
        _store(builder, entered, kbase, builder.add(a_sp, i64(1)), vi)
        reduce = lambda op: cgutils.get_or_insert_function(  # noqa: E731
            builder.module, ir.FunctionType(i64, [vi]), f"llvm.vector.reduce.{op}.v8i64")
        # unsigned: a miss's -1 is the largest key for the minimum, 0 the smallest for the maximum
        near = builder.call(reduce("umin"), [entered])
        far = builder.call(reduce("umax"), [builder.select(ok, key, ir.Constant(vi, [0] * W))])
        ctpop = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(8), [ir.IntType(8)]),
                                               "llvm.ctpop.i8")
        n = builder.zext(builder.call(ctpop, [builder.bitcast(ok, ir.IntType(8))]), i64)
        return context.make_tuple(builder, signature.return_type, [n, near, far])

    return sig, codegen


@intrinsic
def sort8(typingctx, keys, sp):
    """The 8 keys :func:`children8` stored at ``keys[sp + 1 : sp + 9]``, sorted in descending order
    (:data:`NETWORK8`) into ``keys[sp : sp + 8]``: the children entered come first, farthest first,
    so the n - 1 before the nearest are pushed in the order a front-to-back traversal pops them."""
    if not (isinstance(keys, types.Array) and keys.dtype == types.int64):
        return None
    sig = types.none(keys, sp)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        vi = ir.VectorType(i64, W)
        kbase = context.make_array(signature.args[0])(context, builder, value=args[0]).data
        ptr = builder.gep(kbase, [builder.add(args[1], i64(1))])
        v = builder.load(builder.bitcast(ptr, vi.as_pointer()), align=8)
        _store(builder, _sort_desc(builder, v, vi), kbase, args[1], vi)
        return context.get_dummy_value()

    return sig, codegen
