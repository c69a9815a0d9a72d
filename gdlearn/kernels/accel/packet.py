"""Packet traversal: the closest hit or any hit of ``PK`` rays at once, SIMD over the rays.

The scalar traversal (:mod:`gdlearn.kernels.accel.bvh`) runs one ray at a time, SIMD over a leaf's
lanes. Here a *packet* of rays -- the rays of ``PK`` independent paths at the same bounce, see
:mod:`gdlearn.integrators.path.packet` -- walks the tree together: a node is entered when its box is
hit by any ray of the packet that has not found a nearer hit, and each lane of a leaf is tested
against all the rays in one branch-free loop that the compiler vectorises over the rays (no
per-ray setup, reduction or branch, which cost the scalar traversal more than its arithmetic).
Per ray and lane it is the scalar code's arithmetic (``bvh._lane_tuv``), and within a leaf the
winner is the same integer minimum of (distance bits | lane), so with one leaf (small scenes: the
Cornell box) every hit is the scalar code's, bit for bit. In a tree the packet may visit leaves in
another order than a single ray would, which can only change the answer at an exact tie between
leaves (coplanar faces).

The packet lives in the rows of two flat arrays of the caller, ``S`` float64 and ``Q`` int64, one
row of ``PK`` entries per quantity: element ``S[r * PK + j]`` is row r of ray j. A constant row
stride lets the compiler prove that rows do not overlap (with a run-time stride it gave up
vectorising). A ray set is 7 consecutive rows from ``ro``: origin, direction, tmax; a ray with
tmax < 0 is idle and hits nothing. A leaf's spheres and disks (after its lanes) are tested one
primitive at a time against all the rays (:func:`_prim_test`), as the scalar code tests them after
the lanes.
"""
import math

import numpy as np


from gdlearn.kernels.accel.bvh import _KEY_HIGH, _KEY_LOW, _NO_HIT, _f64_bits
from gdlearn.kernels.accel.bvh_build import K_QUAD, LANES, ROW_LIM, ROW_META, WIDE
from gdlearn.kernels.geometry import INFO_TYPE, P_SPHERE, intersect_disk, intersect_sphere
from gdlearn.kernels.jit import leaf
from gdlearn.kernels.vec import fmax, fmin

#: rays per packet (64 float64 per row: 8 AVX-512 vectors)
PK = 64

# float rows used by the traversal: reciprocal directions, the hit's barycentrics, a leaf's best
# lane (t, a, b) while it is tested; the ray sets themselves are the caller's (7 rows from ``ro``)
S_IX, S_IY, S_IZ, S_U, S_V, S_LT, S_LA, S_LB = range(8)
N_S_TRACE = 8
# int rows: the hit primitive (-1: none), a leaf's best key, the any-hit flag
Q_PRIM, Q_LKEY, Q_HIT = range(3)
N_Q_TRACE = 3


@leaf
def _lane_test(nodes, i, n8, S, Q, ro, k, any_hit):
    """Lane ``i`` of a block (row stride n8) against the packet: with ``any_hit`` set the rays' hit
    flags, else keep each ray's smallest key and that lane's t, a, b (rows S_L*)."""
    p0x, p0y, p0z = nodes[i], nodes[i + n8], nodes[i + 2 * n8]
    e1x, e1y, e1z = nodes[i + 3 * n8], nodes[i + 4 * n8], nodes[i + 5 * n8]
    e2x, e2y, e2z = nodes[i + 6 * n8], nodes[i + 7 * n8], nodes[i + 8 * n8]
    lim = nodes[i + ROW_LIM * n8]
    for j in range(PK):
        dx, dy, dz = S[(ro + 3) * PK + j], S[(ro + 4) * PK + j], S[(ro + 5) * PK + j]
        pvx = dy * e2z - dz * e2y
        pvy = dz * e2x - dx * e2z
        pvz = dx * e2y - dy * e2x
        inv = 1.0 / (e1x * pvx + e1y * pvy + e1z * pvz)
        tx, ty, tz = S[ro * PK + j] - p0x, S[(ro + 1) * PK + j] - p0y, S[(ro + 2) * PK + j] - p0z
        a = (tx * pvx + ty * pvy + tz * pvz) * inv
        qx = ty * e1z - tz * e1y
        qy = tz * e1x - tx * e1z
        qz = tx * e1y - ty * e1x
        b = (dx * qx + dy * qy + dz * qz) * inv
        t = (e2x * qx + e2y * qy + e2z * qz) * inv
        ok = ((a >= 0.0) & (b >= 0.0) & (a <= 1.0) & (b <= 1.0) & (a + b <= lim) & (t > 0.0)
              & (t < S[(ro + 6) * PK + j]))
        if any_hit:
            Q[Q_HIT * PK + j] |= np.int64(ok)
        else:
            key = (_f64_bits(t) & _KEY_HIGH) | k | ((np.int64(ok) - 1) & _NO_HIT)
            better = key < Q[Q_LKEY * PK + j]
            Q[Q_LKEY * PK + j] = key if better else Q[Q_LKEY * PK + j]
            S[S_LT * PK + j] = t if better else S[S_LT * PK + j]
            S[S_LA * PK + j] = a if better else S[S_LA * PK + j]
            S[S_LB * PK + j] = b if better else S[S_LB * PK + j]


@leaf
def _adopt(nodes, first, base, lanes, n8, S, Q, ro):
    """Each ray's winner of a leaf becomes its hit (a parallelogram's (a, b) mapped to its triangle
    as ``bvh._lane_prim`` does), and shortens its tmax."""
    for j in range(PK):
        key = Q[Q_LKEY * PK + j]
        got = key != _NO_HIT
        lane = min(key & _KEY_LOW, lanes - 1)          # in the block even without a hit
        a, b = S[S_LA * PK + j], S[S_LB * PK + j]
        meta = np.int64(nodes[base + lane + ROW_META * n8])
        in_a = np.int64(a >= b)
        quad = meta & K_QUAD
        swap = quad & (((meta >> 1) & in_a) | ((meta >> 2) & (1 - in_a)))
        x = abs(a - b) if quad != 0 else a
        y = min(a, b) if quad != 0 else b
        prim = first + (meta >> 3) + (quad & (1 - in_a))
        Q[Q_PRIM * PK + j] = prim if got else Q[Q_PRIM * PK + j]
        S[(ro + 6) * PK + j] = S[S_LT * PK + j] if got else S[(ro + 6) * PK + j]
        S[S_U * PK + j] = (y if swap != 0 else x) if got else S[S_U * PK + j]
        S[S_V * PK + j] = (x if swap != 0 else y) if got else S[S_V * PK + j]


@leaf
def _prim_test(prims, ptype, i, S, Q, ro, any_hit):
    """Primitive ``i`` (a sphere or a disk, of type ``ptype``) against the packet: the scalar
    ``geometry.intersect_prim``'s test per ray, nearer than the ray's tmax (its hit so far)."""
    for j in range(PK):
        tmax = S[(ro + 6) * PK + j]
        o = (S[ro * PK + j], S[(ro + 1) * PK + j], S[(ro + 2) * PK + j])
        d = (S[(ro + 3) * PK + j], S[(ro + 4) * PK + j], S[(ro + 5) * PK + j])
        if ptype == P_SPHERE:       # a leaf's triangles are all in its lanes
            t, u, v = intersect_sphere(prims, i, o, d, 0.0, tmax), 0.0, 0.0
        else:
            t, u, v = intersect_disk(prims, i, o, d, tmax)
        if any_hit:
            Q[Q_HIT * PK + j] |= np.int64(t < tmax)
        elif t < tmax:
            Q[Q_PRIM * PK + j] = i
            S[(ro + 6) * PK + j] = t
            S[S_U * PK + j] = u
            S[S_V * PK + j] = v


@leaf
def _leaf(nodes, node_info, prims, prim_info, node, S, Q, ro, any_hit):
    """Leaf ``node`` against the packet: its lanes, then its other primitives in order (the scalar
    ``bvh._leaf_closest``'s order, so a tie goes the same way)."""
    first, base, lanes = node_info[node, 0], np.int64(node_info[node, 3]), node_info[node, 4]
    ntri = node_info[node, 2]
    if ntri > 0:
        n8 = np.int64(((lanes + LANES - 1) >> 3) << 3)
        if not any_hit:
            for j in range(PK):
                Q[Q_LKEY * PK + j] = _NO_HIT
        for k in range(lanes):
            _lane_test(nodes, base + k, n8, S, Q, ro, k, any_hit)
        if not any_hit:
            _adopt(nodes, first, base, lanes, n8, S, Q, ro)
    for i in range(first + ntri, first + node_info[node, 1]):
        _prim_test(prims, prim_info[i, INFO_TYPE], i, S, Q, ro, any_hit)


@leaf
def _box_any(nodes, b, S, Q, ro, any_hit):
    """Does any ray of the packet (still looking) enter the box of a wide node's child whose
    minimum x is at ``nodes[b]``, before its tmax? The scalar ``bvh._box_hit`` per ray, including
    its 2-ulp widening."""
    lx, ly, lz = nodes[b], nodes[b + WIDE], nodes[b + 2 * WIDE]
    hx, hy, hz = nodes[b + 3 * WIDE], nodes[b + 4 * WIDE], nodes[b + 5 * WIDE]
    hit = np.int64(0)
    for j in range(PK):
        ox, oy, oz = S[ro * PK + j], S[(ro + 1) * PK + j], S[(ro + 2) * PK + j]
        ix, iy, iz = S[S_IX * PK + j], S[S_IY * PK + j], S[S_IZ * PK + j]
        t0, t1 = (lx - ox) * ix, (hx - ox) * ix
        ty0, ty1 = (ly - oy) * iy, (hy - oy) * iy
        tz0, tz1 = (lz - oz) * iz, (hz - oz) * iz
        lo = fmax(fmax(fmin(t0, t1), fmin(ty0, ty1)), fmax(fmin(tz0, tz1), 0.0))
        hi = fmin(fmin(fmax(t0, t1), fmax(ty0, ty1)), fmin(fmax(tz0, tz1), S[(ro + 6) * PK + j]))
        looking = (Q[Q_HIT * PK + j] == 0) if any_hit else True
        hit |= np.int64((lo <= hi * 1.0000000000000004) & looking)
    return hit != 0


@leaf
def _no_hits(Q, any_hit):
    for j in range(PK):
        if any_hit:
            Q[Q_HIT * PK + j] = 0
        else:
            Q[Q_PRIM * PK + j] = -1


@leaf
def packet_trace_leaf(nodes, node_info, prims, prim_info, S, Q, ro, any_hit):
    """:func:`packet_trace` when the whole tree is one leaf (node 0): its lanes and primitives."""
    _no_hits(Q, any_hit)
    _leaf(nodes, node_info, prims, prim_info, 0, S, Q, ro, any_hit)


@leaf
def packet_trace(nodes, node_info, prims, prim_info, S, Q, ro, stack, any_hit):
    """Trace the packet's ray set at row ``ro`` (t in (0, tmax)). Closest hit: Q_PRIM (-1 on a miss)
    and the hit's t (in the tmax row), S_U, S_V; ``any_hit``: Q_HIT is 1 for a blocked ray.
    ``stack`` is the scalar traversal's (its first ``bvh.DEPTH`` entries, as int32 nodes)."""
    if node_info[0, 1] > 0:                       # one leaf: no boxes
        packet_trace_leaf(nodes, node_info, prims, prim_info, S, Q, ro, any_hit)
        return
    _no_hits(Q, any_hit)
    for r in range(3):                            # the slab tests' reciprocal directions
        for j in range(PK):
            dr = S[(ro + 3 + r) * PK + j]
            S[(S_IX + r) * PK + j] = 1.0 / dr if dr != 0.0 else math.copysign(math.inf, dr)
    sp = 0
    node = 0
    while True:
        if node_info[node, 1] > 0:
            _leaf(nodes, node_info, prims, prim_info, node, S, Q, ro, any_hit)
        else:                                     # the children any ray enters; the first is next
            off = np.int64(node_info[node, 0])
            nxt = -1
            for c in range(node_info[node, 2]):
                if _box_any(nodes, off + c, S, Q, ro, any_hit):
                    child = np.int64(nodes[off + 6 * WIDE + c])
                    if nxt >= 0:
                        stack[sp] = child
                        sp += 1
                    else:
                        nxt = child
            if nxt >= 0:
                node = nxt
                continue
        if sp == 0:
            break
        sp -= 1
        node = stack[sp]
