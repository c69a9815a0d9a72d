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

W = 8                                      # lanes per block
_KEY_HIGH = 0x7FFFFFFFFFFFFF00             # see bvh: distance bits, the sign bit cleared
_NO_HIT = 0x7FFFFFFFFFFFFFFF


def _splat(builder, value, vty):
    """``value`` in every lane of a vector of type ``vty``."""
    v = builder.insert_element(ir.Constant(vty, ir.Undefined), value, ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(v, ir.Constant(vty, ir.Undefined), ir.Constant(ir.VectorType(ir.IntType(32), W),
                                                                              [0] * W))


def _load(builder, base, index, vty):
    """The W doubles at ``base[index : index + W]`` as one vector (unaligned load)."""
    ptr = builder.gep(base, [index])
    return builder.load(builder.bitcast(ptr, vty.as_pointer()), align=8)


def _store(builder, vec, base, index, vty):
    builder.store(vec, builder.bitcast(builder.gep(base, [index]), vty.as_pointer()), align=8)


@intrinsic
def block8(typingctx, nodes, i, s, o, d, tmin, tmax, k0, scratch, keep):
    """The smallest nearest-hit key of the 8 lanes ``i .. i+7`` of a block with row stride ``s``
    (``bvh._leaf_lanes``'s keys: distance bits | lane ``k0 + j``, all ones on a miss; hit means
    a, b in [0, 1], a + b <= lim, t > 0, tmin < t < tmax). With ``keep`` the lanes' t, a, b are
    stored at ``scratch[k0 + j]``, ``scratch[64 + k0 + j]``, ``scratch[128 + k0 + j]``."""
    sig = types.int64(nodes, i, s, o, d, tmin, tmax, k0, scratch, keep)

    def codegen(context, builder, signature, args):
        a_nodes, a_i, a_s, a_o, a_d, a_tmin, a_tmax, a_k0, a_scr, a_keep = args
        f64, i64 = ir.DoubleType(), ir.IntType(64)
        vd, vi = ir.VectorType(f64, W), ir.VectorType(i64, W)
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
        inv = builder.fdiv(ir.Constant(vd, [1.0] * W), add(add(mul(e1x, pvx), mul(e1y, pvy)), mul(e1z, pvz)))
        tx, ty, tz = sub(ox, p0x), sub(oy, p0y), sub(oz, p0z)
        a = mul(add(add(mul(tx, pvx), mul(ty, pvy)), mul(tz, pvz)), inv)
        qx = sub(mul(ty, e1z), mul(tz, e1y))
        qy = sub(mul(tz, e1x), mul(tx, e1z))
        qz = sub(mul(tx, e1y), mul(ty, e1x))
        b = mul(add(add(mul(dx, qx), mul(dy, qy)), mul(dz, qz)), inv)
        t = mul(add(add(mul(e2x, qx), mul(e2y, qy)), mul(e2z, qz)), inv)
        zero, one = ir.Constant(vd, [0.0] * W), ir.Constant(vd, [1.0] * W)
        cmp = builder.fcmp_ordered
        ok = builder.and_(cmp(">=", a, zero), cmp(">=", b, zero))
        ok = builder.and_(ok, builder.and_(cmp("<=", a, one), cmp("<=", b, one)))
        ok = builder.and_(ok, cmp("<=", add(a, b), lim))
        ok = builder.and_(ok, builder.and_(cmp(">", t, zero), cmp(">", t, _splat(builder, a_tmin, vd))))
        ok = builder.and_(ok, cmp("<", t, _splat(builder, a_tmax, vd)))
        lane = builder.add(_splat(builder, a_k0, vi), ir.Constant(vi, list(range(W))))
        key = builder.or_(builder.and_(builder.bitcast(t, vi), ir.Constant(vi, [_KEY_HIGH] * W)), lane)
        key = builder.select(ok, key, ir.Constant(vi, [_NO_HIT] * W))
        with builder.if_then(a_keep):
            sbase = context.make_array(signature.args[8])(context, builder, value=a_scr).data
            _store(builder, t, sbase, a_k0, vd)
            _store(builder, a, sbase, builder.add(a_k0, i64(64)), vd)
            _store(builder, b, sbase, builder.add(a_k0, i64(128)), vd)
        smin = cgutils.get_or_insert_function(builder.module, ir.FunctionType(i64, [vi]),
                                              "llvm.vector.reduce.smin.v8i64")
        return builder.call(smin, [key])

    return sig, codegen
