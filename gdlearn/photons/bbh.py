"""A bounding-box hierarchy over photon spheres: every photon whose disc or ball a ray segment crosses.

The beam radiance estimate (Jarosz et al. 2008, Sec. 4, Alg. 1, Fig. 5) needs, for a camera beam,
*all* the photons whose kernel it passes through -- each photon with its own radius. The
hierarchy is built in Jarosz's two steps:

1. a balanced kd-tree over the photon *positions* -- median split along the widest axis of the
   node's points, leaves of at most ``leaf_size`` photons -- the usual O(n log n) build (here by
   quickselect on an index permutation, iteratively, deterministic: ties by index);
2. the BBH pass of Alg. 1: one post-order sweep over the *same topology*, each node's box the union
   of its photons' boxes (position +- radius) and its children's boxes -- linear time.

Nodes are numbered as the build creates them (children after their parent); a leaf has
``left = right = -1`` and owns photons ``start .. start + count`` of the tree order.
``collect`` walks the tree with an explicit stack, tests the segment against the boxes (slab
test; a zero direction component tests the origin against the slab instead of 0 x inf), and
decides each photon exactly (``perp``):

* mode 2 (a disc facing the ray, BRE-2D): d_perp < r and 0 < t_p < tmax;
* mode 3 (a ball, BRE-3D): d_perp < r and the chord [t_p - D, t_p + D], D = sqrt(r^2 - d_perp^2),
  overlaps (0, tmax).

d_perp^2 is computed from the perpendicular offset q = (c - o) - t_p d, never as ``|c - o|^2 - t_p^2``,
which cancels catastrophically for photons far from the ray origin.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from gdlearn.kernels.jit import block, inlined

#: the traversal stack (a balanced tree over 2^60 photons is 60 deep)
STACK = 128


class BBH(NamedTuple):
    pos: np.ndarray       # f64 (n, 3): photon positions in tree order
    radius: np.ndarray    # f64 (n,): their radii
    order: np.ndarray     # i64 (n,): original id of each tree-ordered photon
    lo: np.ndarray        # f64 (m, 3): node boxes
    hi: np.ndarray        # f64 (m, 3)
    left: np.ndarray      # i64 (m,): children (-1 at a leaf)
    right: np.ndarray
    start: np.ndarray     # i64 (m,): a leaf's first photon in tree order
    count: np.ndarray     # i64 (m,): a leaf's photon count (0 for inner nodes)


@inlined
def perp(o, d, c):
    """(t_p, d_perp^2) of the point c against the ray (o, d), d a unit vector (module docstring)."""
    qx = c[0] - o[0]
    qy = c[1] - o[1]
    qz = c[2] - o[2]
    tp = qx * d[0] + qy * d[1] + qz * d[2]
    qx -= tp * d[0]
    qy -= tp * d[1]
    qz -= tp * d[2]
    return tp, qx * qx + qy * qy + qz * qz


@inlined
def crossed(tp, dp2, r, tmax, mode):
    """Does the segment (0, tmax) cross the photon's disc (mode 2) or ball (mode 3)?"""
    if not dp2 < r * r:
        return False
    if mode == 2:
        return 0.0 < tp < tmax
    half = math.sqrt(r * r - dp2)
    return tp + half > 0.0 and tp - half < tmax


@inlined
def segment_box(o, d, tmax, lo, hi):
    """Slab test of the segment o + t d, t in [0, tmax], against the box [lo, hi]; conservative."""
    t0 = 0.0
    t1 = tmax
    for k in range(3):
        if d[k] == 0.0:
            if o[k] < lo[k] or o[k] > hi[k]:
                return False
            continue
        inv = 1.0 / d[k]
        a = (lo[k] - o[k]) * inv
        b = (hi[k] - o[k]) * inv
        if a > b:
            a, b = b, a
        t0 = max(t0, a)
        t1 = min(t1, b)
        if t0 > t1:
            return False
    return True


@block
def _select(idx, pts, lo, hi, k, axis):
    """Quickselect: reorder idx[lo:hi] so that idx[k] holds the median along ``axis`` (ties by index)."""
    while hi - lo > 1:
        mid = (lo + hi) // 2
        pv = pts[idx[mid], axis]
        pi = idx[mid]
        i, j = lo, hi - 1
        while i <= j:
            while pts[idx[i], axis] < pv or (pts[idx[i], axis] == pv and idx[i] < pi):
                i += 1
            while pts[idx[j], axis] > pv or (pts[idx[j], axis] == pv and idx[j] > pi):
                j -= 1
            if i <= j:
                idx[i], idx[j] = idx[j], idx[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j + 1
        elif k >= i:
            lo = i
        else:
            return


@block
def _kdtree(pts, idx, leaf_size, left, right, start, count):
    """Step 1: the kd-tree topology; a child's id is larger than its parent's. Returns the node count."""
    stack = np.empty((STACK, 3), dtype=np.int64)       # (node, lo, hi)
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, pts.shape[0]
    sp = 1
    n_nodes = 1
    while sp > 0:
        sp -= 1
        node, lo, hi = stack[sp, 0], stack[sp, 1], stack[sp, 2]
        start[node] = lo
        if hi - lo <= leaf_size:
            left[node], right[node], count[node] = -1, -1, hi - lo
            continue
        axis = 0
        width = -1.0
        for k in range(3):
            a = math.inf
            b = -math.inf
            for i in range(lo, hi):
                a = min(a, pts[idx[i], k])
                b = max(b, pts[idx[i], k])
            if b - a > width:
                width, axis = b - a, k
        mid = (lo + hi) // 2
        _select(idx, pts, lo, hi, mid, axis)
        left[node], right[node], count[node] = n_nodes, n_nodes + 1, 0
        stack[sp, 0], stack[sp, 1], stack[sp, 2] = n_nodes + 1, mid, hi
        stack[sp + 1, 0], stack[sp + 1, 1], stack[sp + 1, 2] = n_nodes, lo, mid
        sp += 2
        n_nodes += 2
    return n_nodes


@block
def _boxes(pos, radius, left, right, start, count, lo, hi, m):
    """Step 2 (Jarosz et al. 2008, Alg. 1): boxes bottom-up; children have larger ids than their
    parent, so a sweep by decreasing id sees both children before the parent (a post-order)."""
    for node in range(m - 1, -1, -1):
        if right[node] < 0:
            for k in range(3):
                lo[node, k] = math.inf
                hi[node, k] = -math.inf
            for i in range(start[node], start[node] + count[node]):
                for k in range(3):
                    lo[node, k] = min(lo[node, k], pos[i, k] - radius[i])
                    hi[node, k] = max(hi[node, k], pos[i, k] + radius[i])
        else:
            a, b = left[node], right[node]
            for k in range(3):
                lo[node, k] = min(lo[a, k], lo[b, k])
                hi[node, k] = max(hi[a, k], hi[b, k])


def build(pos, radius, leaf_size: int = 4) -> BBH:
    """The hierarchy over photons at ``pos`` (n x 3) with radii ``radius`` (n, or a scalar; > 0)."""
    pts = np.ascontiguousarray(pos, dtype=np.float64).reshape(-1, 3)
    n = pts.shape[0]
    r = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)))
    if n and not (np.isfinite(pts).all() and np.isfinite(r).all() and (r > 0).all()):
        raise ValueError("bbh.build: positions must be finite and radii finite and > 0")
    if int(leaf_size) < 1:
        raise ValueError(f"leaf_size={leaf_size!r} must be >= 1")
    cap = max(2 * n - 1, 1)
    left, right, start, count = (np.full(cap, -1, np.int64) for _ in range(4))
    idx = np.arange(n, dtype=np.int64)
    m = 1
    count[0] = 0
    start[0] = 0
    if n > 0:
        m = _kdtree(pts, idx, int(leaf_size), left, right, start, count)
    left, right, start, count = left[:m].copy(), right[:m].copy(), start[:m].copy(), count[:m].copy()
    tp, tr = pts[idx], r[idx]
    lo, hi = np.empty((m, 3)), np.empty((m, 3))
    _boxes(tp, tr, left, right, start, count, lo, hi, m)
    return BBH(tp, tr, idx, lo, hi, left, right, start, count)


@block
def collect(bbh, o, d, tmax, mode, out):
    """Original ids of the photons whose disc (mode 2) or ball (mode 3) the segment o + t d,
    t in (0, tmax), crosses, into ``out``; returns how many (at most len(out) are written)."""
    n = 0
    if bbh.pos.shape[0] == 0:
        return 0
    stack = np.empty(STACK, dtype=np.int64)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if not segment_box(o, d, tmax, bbh.lo[node], bbh.hi[node]):
            continue
        if bbh.left[node] >= 0:
            stack[sp] = bbh.right[node]
            stack[sp + 1] = bbh.left[node]
            sp += 2
            continue
        for i in range(bbh.start[node], bbh.start[node] + bbh.count[node]):
            tp, dp2 = perp(o, d, bbh.pos[i])
            if crossed(tp, dp2, bbh.radius[i], tmax, mode):
                if n < out.shape[0]:
                    out[n] = bbh.order[i]
                n += 1
    return n
