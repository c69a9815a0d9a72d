"""Bounding volume hierarchy over all primitives: the closest-hit / any-hit traversals.

Built by :mod:`gdlearn.kernels.accel.bvh_build` (binned SAH; triangles, and *quads* -- triangle pairs that
form a parallelogram -- become the lanes of a leaf's block; the binary tree is then collapsed into a
*wide* one of up to ``WIDE`` = 8 children per interior node). Layout: ``node_info`` int32 (M, 5) =
(first, count, ntri, soa, lanes), node 0 the root: a leaf has count > 0 and owns primitives first
.. first+count-1, its ``ntri`` lane primitives (triangles) first; an interior node has count = 0,
its block at ``first`` and ``ntri`` children. ``nodes`` is one flat float64 array of blocks: an
interior node's ``bvh_build.WIDE_ROWS`` rows (its children's box minima x, y, z, maxima x, y, z,
node indices) of 8 lanes, a leaf's ``bvh_build.SOA_ROWS`` rows (p0, e1, e2 by component, lim, meta)
of ``n8`` lanes (``lanes`` rounded up to a multiple of 8, the padding degenerate) at ``soa``.

A leaf's lanes are tested all at once by a branch-free loop the compiler vectorises (8 float64
lanes with AVX-512) instead of one by one with a branch per test: on the Cornell box, one leaf of
18 lanes (6 walls and 12 box faces) replaces a tree of 4-triangle leaves (benchmarks/README.md).

An interior node's 8 children are tested the same way, as one vector slab test
(:func:`gdlearn.kernels.accel.simd.children8`): on the mesh scene a closest-hit ray visits 1.5
wide nodes on average (at most 4 levels above its 139 leaves), and the binary tree's two dependent
slab tests and mispredicted ordering branch per level are gone (benchmarks/README.md: 130 -> 78 ns
per closest hit, the sort of the children included).

Traversal (numba): front-to-back with an explicit stack of *child keys* (a child's entry distance
and node index in one int64, so that integer order is distance order and a popped child is
skipped without a second slab test when a nearer hit was found since). The stack is an int32 array
of ``STACK_SIZE`` the caller allocates once per thread/row and reuses (a per-ray allocation would
cost as much as the traversal itself): its first ``DEPTH`` entries hold the keys, and past them it
doubles as float64 scratch where the vectorised leaf test leaves every lane's t, a, b: the nearest
lane's values are then a load away instead of a dependent recomputation (~30 ns per closest hit on
the Cornell box).

A scene whose tree is one leaf (nine of the ten shipped scenes) is compiled without the tree
traversal: :func:`closest_hit_inline` and :func:`any_hit_inline` pick their code by the BVH's
*form*, the write flag of ``node_info`` (:mod:`gdlearn.kernels.accel.forms`).
"""
import math

import numpy as np
from llvmlite import ir as llvm_ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from gdlearn.kernels.accel.bvh_build import K_A_DIAG, K_B_DIAG, K_QUAD, LANES, ROW_LIM, ROW_META, WIDE, CHILD_MASK, STACK_KEYS, build, build_scene  # noqa: F401
from gdlearn.kernels.geometry import INFO_MAT, INFO_TYPE, intersect_prim
from gdlearn.kernels.accel.simd import block4, block8, children8, sort8
from gdlearn.kernels.layout import MAT_TYPE, NULL
from gdlearn.kernels.accel.forms import one_leaf
from gdlearn.kernels.jit import LEAF_OPTIONS, inlined, leaf, noalloc
from gdlearn.kernels.vec import fmax, fmin

#: traversal stack entries: int64 child keys (two int32 entries each); a wide node pushes at most
#: 7, and the build checks that 7 per level of its tree (plus the 8 a push writes) fit
KEYS = STACK_KEYS
DEPTH = 2 * KEYS
#: the leaf test's scratch: t, a, b of up to LEAF_MAX lanes as float64 (two int32 entries each)
_SCRATCH = 64
STACK_SIZE = DEPTH + 2 * 3 * _SCRATCH
_CHILD = np.int64(CHILD_MASK)
_DIST = np.int64(~CHILD_MASK)

# nearest-hit keys of _leaf_lanes: distance bits above, the lane below
_KEY_LOW = np.int64(0xFF)
_KEY_HIGH = np.int64(0x7FFFFFFFFFFFFF00)     # the sign bit cleared too
_NO_HIT = np.int64(0x7FFFFFFFFFFFFFFF)
_U2, _U3, _U4, _U5, _U6, _U7, _U8, _U9 = (np.uint64(r) for r in range(2, 10))


# --------------------------------------------------------------------------------------- traversal
def _stack_view(dtype, tail):
    """An intrinsic: the 8-byte ``dtype`` array over the int32 stack's tail ``stack[DEPTH:]``
    (``tail``) or its head ``stack[:DEPTH]`` -- the same memory, no reference count, valid while the
    stack lives (the caller's row or thread). A stack shorter than DEPTH has an empty tail."""
    aty = types.Array(dtype, 1, "C")

    def typer(typingctx, stack):
        if not (isinstance(stack, types.Array) and stack.dtype == types.int32 and stack.ndim == 1):
            return None

        def codegen(context, builder, signature, args):
            src = context.make_array(stack)(context, builder, value=args[0])
            dst = context.make_array(aty)(context, builder)
            i64 = llvm_ir.IntType(64)
            size = builder.extract_value(src.shape, 0)
            big = builder.icmp_signed(">", size, i64(DEPTH))
            if tail:
                n = builder.select(big, builder.sdiv(builder.sub(size, i64(DEPTH)), i64(2)), i64(0))
                data = builder.gep(src.data, [i64(DEPTH)])
            else:
                n = builder.sdiv(builder.select(big, i64(DEPTH), size), i64(2))
                data = src.data
            context.populate_array(dst, data=builder.bitcast(data, dst.data.type),
                                   shape=cgutils.pack_array(builder, [n]),
                                   strides=cgutils.pack_array(builder, [i64(8)]), itemsize=i64(8),
                                   meminfo=None)
            return dst._getvalue()

        return aty(stack), codegen

    typer.__name__ = typer.__qualname__ = "_scratch" if tail else "_keys"
    return intrinsic(typer)


#: float64 scratch over the stack's tail: the leaf test's t, a, b per lane
_scratch = _stack_view(types.float64, tail=True)
#: int64 child keys over the stack's head: the traversal's stack proper
_keys = _stack_view(types.int64, tail=False)


@intrinsic
def _f64_bits(typingctx, x):
    """The IEEE-754 bits of a float64 as an int64 (a bitcast: no instruction at all)."""
    if not isinstance(x, types.Float):
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.IntType(64))

    return types.int64(types.float64), codegen


@inlined
def _box_hit(nodes, off, c, o, inv, tmin, tmax):
    """Slab test of child c of the wide node whose block starts at ``off``; returns the entry
    distance or inf. :func:`gdlearn.kernels.accel.simd.children8` does this for 8 children at once."""
    b = np.int64(off) + c
    t0 = (nodes[b] - o[0]) * inv[0]
    t1 = (nodes[b + 3 * WIDE] - o[0]) * inv[0]
    ty0 = (nodes[b + WIDE] - o[1]) * inv[1]
    ty1 = (nodes[b + 4 * WIDE] - o[1]) * inv[1]
    tz0 = (nodes[b + 2 * WIDE] - o[2]) * inv[2]
    tz1 = (nodes[b + 5 * WIDE] - o[2]) * inv[2]
    # per axis the near and far slab; a NaN (0 * inf: origin on a slab, ray parallel) is ignored
    lo = fmax(fmax(fmin(t0, t1), fmin(ty0, ty1)), fmax(fmin(tz0, tz1), tmin))
    hi = fmin(fmin(fmax(t0, t1), fmax(ty0, ty1)), fmin(fmax(tz0, tz1), tmax)) * 1.0000000000000004
    if lo <= hi:                                                           # 2 ulp: no leaks at box faces
        return lo
    return math.inf


@inlined
def _inv_dir(d):
    # 1/0 = +-inf is what the slab test wants; numba raises on float division by zero, so spell it out
    ix = 1.0 / d[0] if d[0] != 0.0 else math.copysign(math.inf, d[0])
    iy = 1.0 / d[1] if d[1] != 0.0 else math.copysign(math.inf, d[1])
    iz = 1.0 / d[2] if d[2] != 0.0 else math.copysign(math.inf, d[2])
    return (ix, iy, iz)


@inlined
def _lane_tuv(nodes, i, s, o, d):
    """Moeller-Trumbore on lane i of a block with row stride s: (t, a, b), the parameters along the
    lane's edges e1, e2 (NaN / inf when the ray is parallel or the lane is padding)."""
    e1x, e1y, e1z = nodes[i + _U3 * s], nodes[i + _U4 * s], nodes[i + _U5 * s]
    e2x, e2y, e2z = nodes[i + _U6 * s], nodes[i + _U7 * s], nodes[i + _U8 * s]
    pvx = d[1] * e2z - d[2] * e2y
    pvy = d[2] * e2x - d[0] * e2z
    pvz = d[0] * e2y - d[1] * e2x
    inv = 1.0 / (e1x * pvx + e1y * pvy + e1z * pvz)       # det = 0: inf, and a, b, t fail the tests
    tx, ty, tz = o[0] - nodes[i], o[1] - nodes[i + s], o[2] - nodes[i + _U2 * s]
    a = (tx * pvx + ty * pvy + tz * pvz) * inv
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    b = (d[0] * qx + d[1] * qy + d[2] * qz) * inv
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    return t, a, b


@inlined
def _leaf_lanes(nodes, base, lanes, o, d, tmin, tmax, scratch, keep):
    """The lane (0 .. lanes-1) of a leaf's block with the nearest hit in (tmin, tmax), or -1.

    A lane is hit when a, b >= 0, a, b <= 1 and a + b <= lim (1: triangle, 2: parallelogram),
    tested 8 lanes at a time (:func:`gdlearn.kernels.accel.simd.block8`, :func:`_lane_tuv`'s arithmetic;
    a last block of at most 4 lanes by :func:`~gdlearn.kernels.accel.simd.block4`).
    The nearest hit is an integer minimum of the distance's IEEE bits (monotone for t > 0) with the
    lane in the low 8 bits; two hits closer than 2^-44 relative may be resolved by lane order, both
    are on the ray to within rounding. With ``keep`` every lane's t, a, b go to ``scratch``
    [0, 64, 128 + lane].
    """
    nb = (lanes + LANES - 1) >> 3
    s = np.int64(nb << 3)
    b0 = np.int64(base)
    best = _NO_HIT
    for blk in range(nb):
        k0 = np.int64(blk << 3)
        if lanes - k0 <= 4:                    # a last block of 1-4 lanes: half the vector
            key = block4(nodes, b0 + k0, s, o, d, tmin, tmax, k0, scratch, keep)
        else:
            key = block8(nodes, b0 + k0, s, o, d, tmin, tmax, k0, scratch, keep)
        best = key if key < best else best
    if best == _NO_HIT:
        return -1
    return best & _KEY_LOW


@inlined
def _lane_prim(nodes, base, lanes, lane, o, d, scratch, keep):
    """(t, rank of the primitive in its leaf, u, v) of a lane :func:`_leaf_lanes` found hit (its
    t, a, b from the scratch), a parallelogram's (a, b) mapped to the triangle of the pair that
    contains the point and that triangle's barycentrics (bvh_build module docstring)."""
    s = np.uint64(((lanes + LANES - 1) >> 3) << 3)
    i = np.uint64(base) + np.uint64(lane)
    if keep:
        t, a, b = scratch[lane], scratch[lane + _SCRATCH], scratch[lane + 2 * _SCRATCH]
    else:                                        # a caller's short stack: compute the lane again
        t, a, b = _lane_tuv(nodes, i, s, o, d)
    meta = np.int64(nodes[i + np.uint64(ROW_META) * s])
    # integer arithmetic and selects, no branch: which triangle of a quad holds the point is a coin
    # toss per ray, and the mispredicted branches cost ~12 ns per hit (more than the rest of this).
    # A = (p0, p0 + E1, p0 + E1 + E3) holds a >= b, B = (p0, p0 + E1 + E3, p0 + E3) the rest; in both
    # the barycentrics are (|a - b|, min(a, b)), swapped when that triangle's e1 is the diagonal
    in_a = np.int64(a >= b)
    quad = meta & K_QUAD
    swap = quad & (((meta >> 1) & in_a) | ((meta >> 2) & (1 - in_a)))     # K_A_DIAG, K_B_DIAG bits
    rank = (meta >> 3) + (quad & (1 - in_a))
    x = abs(a - b) if quad != 0 else a
    y = min(a, b) if quad != 0 else b
    return t, rank, y if swap != 0 else x, x if swap != 0 else y


# no reference counting (_nrt=False) in the traversals: they allocate nothing, and a count on the
# scratch view would be a non-inlinable call per ray
@noalloc
def closest_hit(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """(t, prim, u, v) of the nearest hit in (tmin, tmax); prim = -1 on a miss."""
    return closest_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack)


@leaf
def _leaf_closest(nodes, node_info, prims, prim_info, node, o, d, tmin, best, scratch, keep):
    """``best`` = (t, prim, u, v) updated with the hits of leaf ``node`` nearer than best t."""
    best_t, best_p, best_u, best_v = best
    first = node_info[node, 0]
    ntri = node_info[node, 2]                 # a leaf's triangles come first
    if ntri > 0:
        lanes = node_info[node, 4]
        k = _leaf_lanes(nodes, node_info[node, 3], lanes, o, d, tmin, best_t, scratch, keep)
        if k >= 0:
            best_t, r, best_u, best_v = _lane_prim(nodes, node_info[node, 3], lanes, k, o, d, scratch, keep)
            best_p = first + r
    for i in range(first + ntri, first + node_info[node, 1]):
        t, u, v = intersect_prim(prims, prim_info[i, INFO_TYPE], i, o, d, tmin, best_t)
        if t < best_t:
            best_t, best_p, best_u, best_v = t, i, u, v
    return best_t, best_p, best_u, best_v


def closest_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """:func:`closest_hit` inlined into the caller by LLVM (the path tracers' hot loop: a call
    passes four arrays as ~30 scalars, which costs more than a small scene's whole traversal).
    Compiled for the BVH's form (:mod:`gdlearn.kernels.accel.forms`): a one-leaf scene's kernels
    test the leaf and leave the tree traversal out."""
    raise NotImplementedError("compiled code only: call closest_hit")


@overload(closest_hit_inline, jit_options=LEAF_OPTIONS)
def _closest_hit_typed(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    body = _closest_hit_leaf if one_leaf(node_info) else _closest_hit_tree

    def impl(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
        return body(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack)

    return impl


@leaf
def _closest_hit_leaf(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """:func:`closest_hit_inline` when the whole tree is one leaf (small scenes)."""
    scratch = _scratch(stack)
    keep = scratch.shape[0] >= 3 * _SCRATCH     # False for a caller's short stack (then: recompute)
    best = _leaf_closest(nodes, node_info, prims, prim_info, 0, o, d, tmin, (tmax, -1, 0.0, 0.0), scratch, keep)
    if best[1] < 0:
        return math.inf, -1, 0.0, 0.0
    return best


@leaf
def _closest_hit_tree(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """:func:`closest_hit_inline` for any tree (one leaf included, tested at run time)."""
    if node_info[0, 1] > 0:
        return _closest_hit_leaf(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack)
    scratch = _scratch(stack)
    keep = scratch.shape[0] >= 3 * _SCRATCH
    best = _tree_closest(nodes, node_info, prims, prim_info, o, d, tmin, (tmax, -1, 0.0, 0.0), stack, scratch, keep)
    if best[1] < 0:
        return math.inf, -1, 0.0, 0.0
    return best


@inlined
def _push_children(keys, sp, n, far):
    """Push the n - 1 children (n >= 1) a ray enters besides the nearest, farthest first (their
    keys from :func:`gdlearn.kernels.accel.simd.children8`); returns the new stack size. One other
    child is pushed as it is (no branch: with none, the store is past the stack's top), more are
    sorted first."""
    keys[sp] = far
    if n > 2:
        sort8(keys, sp)
    return sp + n - 1


@leaf
def _tree_closest(nodes, node_info, prims, prim_info, o, d, tmin, best, stack, scratch, keep):
    """Front-to-back traversal of a tree whose root is a wide interior node: the children a ray
    enters are visited nearest first (:func:`_push_children` pushes the others farthest first), and
    a popped child is skipped when its entry distance is past the best hit found since."""
    inv = _inv_dir(d)
    keys = _keys(stack)
    sp = 0
    node = np.int64(0)
    while True:
        if node_info[node, 1] > 0:
            best = _leaf_closest(nodes, node_info, prims, prim_info, node, o, d, tmin, best, scratch, keep)
        else:
            n, near, far = children8(nodes, np.int64(node_info[node, 0]), o, inv, tmin, best[0], keys, sp)
            if n > 0:
                sp = _push_children(keys, sp, n, far)
                node = near & _CHILD
                continue
        found = False
        bits = _f64_bits(best[0])
        while sp > 0:
            sp -= 1
            k = keys[sp]
            if k & _DIST <= bits:                # distances >= +0: their bits are ordered as they are
                node = k & _CHILD
                found = True
                break
        if not found:
            break
    return best


@noalloc
def any_hit(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    """Index of some primitive hit in (tmin, tmax), or -1 (of a parallelogram lane: its first
    triangle). With ``skip_null``, primitives whose material is a null BSDF
    (``materials[m, 0] == NULL``) are ignored (they only bound media)."""
    return any_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials)


def any_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    """:func:`any_hit` inlined into the caller by LLVM (see :func:`closest_hit_inline`), compiled
    for the BVH's form as it is."""
    raise NotImplementedError("compiled code only: call any_hit")


@overload(any_hit_inline, jit_options=LEAF_OPTIONS)
def _any_hit_typed(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    body = _any_hit_leaf if one_leaf(node_info) else _any_hit_tree

    def impl(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
        return body(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials)

    return impl


@leaf
def _leaf_any(nodes, node_info, prims, prim_info, node, o, d, tmin, tmax, scratch, skip_null, materials):
    """Index of some primitive of leaf ``node`` hit in (tmin, tmax), or -1 (see :func:`any_hit`)."""
    first = node_info[node, 0]
    ntri = node_info[node, 2]
    ntri_done = 0
    if ntri > 0 and not skip_null:
        lanes = node_info[node, 4]
        base = node_info[node, 3]
        k = _leaf_lanes(nodes, base, lanes, o, d, tmin, tmax, scratch, False)   # any hit will do
        if k >= 0:                       # the lane's first triangle (of a parallelogram: A)
            n8 = np.uint64(((lanes + LANES - 1) >> 3) << 3)
            return first + (int(nodes[np.uint64(base) + np.uint64(k) + np.uint64(ROW_META) * n8]) >> 3)
        ntri_done = ntri
    for i in range(first + ntri_done, first + node_info[node, 1]):
        if skip_null and materials[prim_info[i, INFO_MAT], MAT_TYPE] == NULL:
            continue
        t, u, v = intersect_prim(prims, prim_info[i, INFO_TYPE], i, o, d, tmin, tmax)
        if t < math.inf:
            return i
    return -1


@leaf
def _any_hit_leaf(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    """:func:`any_hit_inline` when the whole tree is one leaf."""
    return _leaf_any(nodes, node_info, prims, prim_info, 0, o, d, tmin, tmax, _scratch(stack), skip_null, materials)


@leaf
def _any_hit_tree(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    """:func:`any_hit_inline` for any tree: the children a ray enters, nearest first."""
    if node_info[0, 1] > 0:
        return _any_hit_leaf(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials)
    scratch = _scratch(stack)
    keys = _keys(stack)
    inv = _inv_dir(d)
    sp = 0
    node = np.int64(0)
    while True:
        if node_info[node, 1] > 0:
            hit = _leaf_any(nodes, node_info, prims, prim_info, node, o, d, tmin, tmax, scratch, skip_null, materials)
            if hit >= 0:
                return hit
        else:
            n, near, far = children8(nodes, np.int64(node_info[node, 0]), o, inv, tmin, tmax, keys, sp)
            if n > 0:
                sp = _push_children(keys, sp, n, far)
                node = near & _CHILD
                continue
        if sp == 0:
            break
        sp -= 1
        node = keys[sp] & _CHILD
    return -1
