"""Bounding volume hierarchy over all primitives, and the closest-hit / any-hit traversals.

Build (Python + numpy, once per scene): binned surface-area heuristic (Wald 2007, "On fast
construction of SAH-based bounding volume hierarchies"), 12 bins per axis, with costs measured for
the traversal below (``C_*``), leaves of at most ``LEAF_MAX`` primitives. The primitives are then
*reordered* so that every leaf is a contiguous range (``build`` returns the permutation;
:mod:`gdlearn.scene.compile` applies it), which spares the traversal one indirection.

Layout (``pack``): ``node_info`` int32 (M, 4) = (first, count, axis or ntri, soa): a leaf has
count > 0 and owns primitives first .. first+count-1, its ``ntri`` triangles first; an interior
node has count = 0, children ``first`` and ``first + 1``, split along ``axis``. ``nodes`` is one
flat float64 array: node k's box (min, max) at ``6 k``, then every leaf's triangles copied in
structure-of-arrays form -- 9 rows (p0, e1, e2 by component) of ``n8`` lanes (ntri rounded up to a
multiple of 8, the padding degenerate) starting at ``node_info[leaf, 3]``. A leaf's triangles are
then tested all at once by a branch-free loop the compiler vectorises (8 float64 lanes with
AVX-512), instead of one by one with a branch per test: on the Cornell box's 36 triangles, one
leaf of lanes beats a tree of 4-triangle leaves several times over (benchmarks/README.md).

Traversal (numba): front-to-back with an explicit stack. The stack is an int32 array of
``STACK_SIZE`` the caller allocates once per thread/row and reuses (a per-ray allocation would cost
as much as the traversal itself).
"""
import math

import numpy as np
from llvmlite import ir as llvm_ir
from numba import njit, types
from numba.extending import intrinsic

from .geometry import INFO_MAT, INFO_TYPE, P_TRIANGLE, intersect_prim, intersect_triangle
from .layout import MAT_TYPE, NULL

N_BINS = 12
#: SAH costs in units of one triangle lane of a vectorised leaf, measured on this machine with
#: benchmarks/bench_kernels.py: visiting an interior node (two slab tests, ordering, stack), starting
#: a leaf, testing a sphere or disk (scalar). A leaf holds at most LEAF_MAX primitives (the rank of a
#: triangle must fit the 8 low bits of a nearest-hit key).
C_NODE = 16.0
C_LEAF = 2.0
C_TRI = 1.0
C_PRIM = 6.0
LEAF_MAX = 64
STACK_SIZE = 64
#: lanes of a leaf's triangle block (a multiple of the SIMD width: 8 float64 with AVX-512)
LANES = 8
SOA_ROWS = 9

# nearest-hit keys of _leaf_triangles: distance bits above, the triangle's rank in the leaf below
_KEY_LOW = np.int64(0xFF)
_KEY_HIGH = np.int64(0x7FFFFFFFFFFFFF00)     # the sign bit cleared too
_NO_HIT = np.int64(0x7FFFFFFFFFFFFFFF)
_U2, _U3, _U4, _U5, _U6, _U7, _U8 = (np.uint64(r) for r in range(2, 9))


# ------------------------------------------------------------------------------------------- build
def build(lo: np.ndarray, hi: np.ndarray, kinds: np.ndarray | None = None):
    """Binned-SAH BVH over boxes ``lo``/``hi`` (N x 3) of primitives of types ``kinds``
    (``geometry.P_*``; None: no triangles). Returns (nodes, node_info, order): leaf ranges index
    the primitives *after* reordering by ``order``; a leaf's triangles come first, and
    ``node_info[leaf, 2]`` counts them (they are tested together, vectorised). Boxes are (M, 6)
    and info (M, 3); :func:`pack` turns them into the traversal's arrays."""
    n = len(lo)
    if n == 0:
        raise ValueError("a BVH needs at least one primitive")
    tri = np.zeros(n, dtype=bool) if kinds is None else (np.asarray(kinds) == P_TRIANGLE)
    cost = np.where(tri, C_TRI, C_PRIM)
    cen = 0.5 * (lo + hi)
    nodes, info = [], []
    order = np.empty(n, dtype=np.int64)
    filled = 0
    # explicit work list: (node index, primitive indices)
    nodes.append(None)
    info.append(None)
    work = [(0, np.arange(n))]
    while work:
        k, idx = work.pop()
        blo, bhi = lo[idx].min(axis=0), hi[idx].max(axis=0)
        nodes[k] = np.concatenate([blo, bhi])
        split = _sah_split(lo[idx], hi[idx], cen[idx], cost[idx]) if len(idx) > 2 else None
        if split is None:
            idx = idx[np.argsort(~tri[idx], kind="stable")]         # triangles first
            order[filled:filled + len(idx)] = idx
            info[k] = (filled, len(idx), int(tri[idx].sum()))
            filled += len(idx)
            continue
        axis, left_mask = split
        c = len(nodes)
        nodes += [None, None]
        info += [None, None]
        info[k] = (c, 0, axis)
        work.append((c + 1, idx[~left_mask]))
        work.append((c, idx[left_mask]))
    return (np.ascontiguousarray(np.array(nodes, dtype=np.float64)),
            np.ascontiguousarray(np.array(info, dtype=np.int32)), order)


def _area(ext):
    return 2.0 * (ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0])


def _sah_split(lo, hi, cen, cost):
    """The cheapest binned split (axis, mask of the left side), or None if a leaf is cheaper.
    SAH with the measured costs C_NODE, C_TRI, C_PRIM (a leaf holds at most LEAF_MAX primitives)."""
    n = len(cen)
    clo, chi = cen.min(axis=0), cen.max(axis=0)
    best = (math.inf, None, None)
    for axis in range(3):
        ext = chi[axis] - clo[axis]
        if ext <= 0.0:
            continue
        b = np.minimum((N_BINS * (cen[:, axis] - clo[axis]) / ext).astype(np.int64), N_BINS - 1)
        cnt = np.bincount(b, minlength=N_BINS)
        wsum = np.bincount(b, weights=cost, minlength=N_BINS)
        blo = np.full((N_BINS, 3), np.inf)
        bhi = np.full((N_BINS, 3), -np.inf)
        np.minimum.at(blo, b, lo)
        np.maximum.at(bhi, b, hi)
        for s in range(1, N_BINS):
            if cnt[:s].sum() == 0 or cnt[s:].sum() == 0:
                continue
            al = _area(bhi[:s].max(0) - blo[:s].min(0))
            ar = _area(bhi[s:].max(0) - blo[s:].min(0))
            c = al * (C_LEAF + wsum[:s].sum()) + ar * (C_LEAF + wsum[s:].sum())
            if c < best[0]:
                best = (c, axis, b < s)
    if best[1] is None:
        if n > LEAF_MAX:   # all centroids coincide: split the list in half to bound leaf size
            mask = np.zeros(n, dtype=bool)
            mask[: n // 2] = True
            return 0, mask
        return None
    parent = _area(hi.max(0) - lo.min(0))
    if n <= LEAF_MAX and parent * (C_LEAF + cost.sum()) <= parent * C_NODE + best[0]:
        return None                 # SAH: one leaf is cheaper than two children
    return best[1], best[2]


def pack(boxes: np.ndarray, info: np.ndarray, prims: np.ndarray):
    """(nodes, node_info) in the traversal's layout (module docstring) from ``build``'s boxes
    (M x 6) and info (M x 3) and the primitive rows *in BVH order*."""
    m = len(boxes)
    node_info = np.zeros((m, 4), dtype=np.int32)
    node_info[:, :3] = info
    parts = [np.asarray(boxes, dtype=np.float64).reshape(-1)]
    off = 6 * m
    for k in range(m):
        first, count, ntri = info[k]
        if count == 0 or ntri == 0:
            continue
        n8 = -(-ntri // LANES) * LANES
        block = np.zeros((SOA_ROWS, n8))     # padding lanes: zero edges, det = 0, never hit
        block[:, :ntri] = prims[first:first + ntri, 0:SOA_ROWS].T
        node_info[k, 3] = off
        parts.append(block.reshape(-1))
        off += block.size
    return np.ascontiguousarray(np.concatenate(parts)), node_info


# --------------------------------------------------------------------------------------- traversal
@intrinsic
def _f64_bits(typingctx, x):
    """The IEEE-754 bits of a float64 as an int64 (a bitcast: no instruction at all)."""
    if not isinstance(x, types.Float):
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.IntType(64))

    return types.int64(types.float64), codegen


@njit(cache=True, error_model="numpy", forceinline=True)
def _fmin(a, b):
    # written out: the builtin min/max are calls numba does not always inline
    return b if b < a else a


@njit(cache=True, error_model="numpy", forceinline=True)
def _fmax(a, b):
    return b if b > a else a


@njit(cache=True, error_model="numpy", forceinline=True)
def _box_hit(nodes, k, o, inv, tmin, tmax):
    """Slab test of node k; returns the entry distance or inf."""
    b = 6 * k
    t0 = (nodes[b] - o[0]) * inv[0]
    t1 = (nodes[b + 3] - o[0]) * inv[0]
    ty0 = (nodes[b + 1] - o[1]) * inv[1]
    ty1 = (nodes[b + 4] - o[1]) * inv[1]
    tz0 = (nodes[b + 2] - o[2]) * inv[2]
    tz1 = (nodes[b + 5] - o[2]) * inv[2]
    # per axis the near and far slab; a NaN (0 * inf: origin on a slab, ray parallel) is ignored
    lo = _fmax(_fmax(_fmin(t0, t1), _fmin(ty0, ty1)), _fmax(_fmin(tz0, tz1), tmin))
    hi = _fmin(_fmin(_fmax(t0, t1), _fmax(ty0, ty1)), _fmin(_fmax(tz0, tz1), tmax)) * 1.0000000000000004
    if lo <= hi:                                                           # 2 ulp: no leaks at box faces
        return lo
    return math.inf


@njit(cache=True, error_model="numpy", forceinline=True)
def _inv_dir(d):
    # 1/0 = +-inf is what the slab test wants; numba raises on float division by zero, so spell it out
    ix = 1.0 / d[0] if d[0] != 0.0 else math.copysign(math.inf, d[0])
    iy = 1.0 / d[1] if d[1] != 0.0 else math.copysign(math.inf, d[1])
    iz = 1.0 / d[2] if d[2] != 0.0 else math.copysign(math.inf, d[2])
    return (ix, iy, iz)


@njit(cache=True, error_model="numpy", forceinline=True)
def _leaf_triangles(nodes, base, ntri, o, d, tmin, tmax):
    """Rank (0 .. ntri-1) of the nearest triangle of a leaf's block hit in (tmin, tmax), or -1.

    One branch-free pass over the block's lanes that the compiler vectorises: each lane is
    :func:`geometry.intersect_triangle`'s arithmetic (Moeller-Trumbore), and the nearest hit is an
    integer minimum of the distance's IEEE bits (monotone for t > 0) with the lane in the low 8 bits.
    The caller recomputes the winner's exact t, u, v; two hits closer than 2^-44 relative may be
    resolved by lane order, both are on the ray to within rounding."""
    ox, oy, oz = o
    dx, dy, dz = d
    n8 = ((ntri + LANES - 1) >> 3) << 3      # known multiple of 8: no scalar remainder loop
    # unsigned indices: a signed one gets numba's negative-index wrap-around, which turns the
    # contiguous lane loads into gathers
    ub = np.uint64(base)
    s = np.uint64(n8)
    best = _NO_HIT
    for k in range(n8):
        i = ub + np.uint64(k)
        p0x, p0y, p0z = nodes[i], nodes[i + s], nodes[i + _U2 * s]
        e1x, e1y, e1z = nodes[i + _U3 * s], nodes[i + _U4 * s], nodes[i + _U5 * s]
        e2x, e2y, e2z = nodes[i + _U6 * s], nodes[i + _U7 * s], nodes[i + _U8 * s]
        pvx = dy * e2z - dz * e2y
        pvy = dz * e2x - dx * e2z
        pvz = dx * e2y - dy * e2x
        inv = 1.0 / (e1x * pvx + e1y * pvy + e1z * pvz)       # det = 0: inf, and u, v, t fail below
        tx, ty, tz = ox - p0x, oy - p0y, oz - p0z
        u = (tx * pvx + ty * pvy + tz * pvz) * inv
        qx = ty * e1z - tz * e1y
        qy = tz * e1x - tx * e1z
        qz = tx * e1y - ty * e1x
        v = (dx * qx + dy * qy + dz * qz) * inv
        t = (e2x * qx + e2y * qy + e2z * qz) * inv
        ok = (u >= 0.0) & (u <= 1.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0) & (t > tmin) & (t < tmax)
        # no branch (a conditional expression here would stop the vectoriser): a miss ors in all ones
        key = (_f64_bits(t) & _KEY_HIGH) | k | ((np.int64(ok) - 1) & _NO_HIT)
        best = key if key < best else best
    if best == _NO_HIT:
        return -1
    return best & _KEY_LOW


@njit(cache=True, error_model="numpy")
def closest_hit(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """(t, prim, u, v) of the nearest hit in (tmin, tmax); prim = -1 on a miss."""
    return closest_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack)


@njit(cache=True, error_model="numpy", forceinline=True)
def closest_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """:func:`closest_hit` inlined into the caller by LLVM (the path tracers' hot loop: a call
    passes four arrays as ~30 scalars, which costs more than a small scene's whole traversal)."""
    # the slab tests' reciprocal direction: not needed when the whole tree is one leaf
    inv = _inv_dir(d) if node_info[0, 1] == 0 else (0.0, 0.0, 0.0)
    best_t = tmax
    best_p = -1
    best_u = 0.0
    best_v = 0.0
    sp = 0
    node = 0
    while True:
        first = node_info[node, 0]
        count = node_info[node, 1]
        if count > 0:
            ntri = node_info[node, 2]                 # a leaf's triangles come first
            if ntri > 0:
                r = _leaf_triangles(nodes, node_info[node, 3], ntri, o, d, tmin, best_t)
                if r >= 0:
                    i = first + r
                    best_t, best_u, best_v = intersect_triangle(prims, i, o, d, math.inf)
                    best_p = i
            for i in range(first + ntri, first + count):
                t, u, v = intersect_prim(prims, prim_info[i, INFO_TYPE], i, o, d, tmin, best_t)
                if t < best_t:
                    best_t, best_p, best_u, best_v = t, i, u, v
        else:
            a = first
            b = first + 1
            ta = _box_hit(nodes, a, o, inv, tmin, best_t)
            tb = _box_hit(nodes, b, o, inv, tmin, best_t)
            if tb < ta:                        # visit the nearer child first
                a, b = b, a
                ta, tb = tb, ta
            if ta < math.inf:
                if tb < math.inf:
                    stack[sp] = b
                    sp += 1
                node = a
                continue
            if tb < math.inf:
                node = b
                continue
        # pop the next node still in front of the best hit
        found = False
        while sp > 0:
            sp -= 1
            node = stack[sp]
            if _box_hit(nodes, node, o, inv, tmin, best_t) < math.inf:
                found = True
                break
        if not found:
            break
    if best_p < 0:
        return math.inf, -1, 0.0, 0.0
    return best_t, best_p, best_u, best_v


@njit(cache=True, error_model="numpy")
def any_hit(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    """Index of some primitive hit in (tmin, tmax), or -1. With ``skip_null``, primitives whose
    material is a null BSDF (``materials[m, 0] == NULL``) are ignored (they only bound media)."""
    return any_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials)


@njit(cache=True, error_model="numpy", forceinline=True)
def any_hit_inline(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack, skip_null, materials):
    """:func:`any_hit` inlined into the caller by LLVM (see :func:`closest_hit_inline`)."""
    inv = (0.0, 0.0, 0.0)
    if node_info[0, 1] == 0:          # a tree, not one leaf: cull by the root's box first
        inv = _inv_dir(d)
        if _box_hit(nodes, 0, o, inv, tmin, tmax) == math.inf:
            return -1
    sp = 0
    node = 0
    while True:
        first = node_info[node, 0]
        count = node_info[node, 1]
        if count > 0:
            ntri = node_info[node, 2]
            if ntri > 0 and not skip_null:
                r = _leaf_triangles(nodes, node_info[node, 3], ntri, o, d, tmin, tmax)
                if r >= 0:
                    return first + r
                ntri_done = ntri
            else:
                ntri_done = 0
            for i in range(first + ntri_done, first + count):
                if skip_null and materials[prim_info[i, INFO_MAT], MAT_TYPE] == NULL:
                    continue
                t, u, v = intersect_prim(prims, prim_info[i, INFO_TYPE], i, o, d, tmin, tmax)
                if t < math.inf:
                    return i
        else:
            a = first
            b = first + 1
            ta = _box_hit(nodes, a, o, inv, tmin, tmax)
            tb = _box_hit(nodes, b, o, inv, tmin, tmax)
            if ta < math.inf:
                if tb < math.inf:
                    stack[sp] = b
                    sp += 1
                node = a
                continue
            if tb < math.inf:
                node = b
                continue
        if sp == 0:
            break
        sp -= 1
        node = stack[sp]
    return -1
