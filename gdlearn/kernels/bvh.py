"""Bounding volume hierarchy over all primitives, and the closest-hit / any-hit traversals.

Build (Python + numpy, once per scene): binned surface-area heuristic (Wald 2007, "On fast
construction of SAH-based bounding volume hierarchies"), 12 bins per axis, leaves of at most
``LEAF_SIZE`` primitives. The primitives are then *reordered* so that every leaf is a contiguous
range (``build`` returns the permutation; :mod:`gdlearn.scene.compile` applies it), which spares
the traversal one indirection.

Nodes: ``nodes`` float64 (M, 6) = box min, box max; ``node_info`` int32 (M, 3) = (first, count,
axis): a leaf has count > 0 and owns primitives first .. first+count-1; an interior node has
count = 0, children ``first`` and ``first + 1``, split along ``axis``.

Traversal (numba): front-to-back with an explicit stack. The stack is an int32 array of
``STACK_SIZE`` the caller allocates once per thread/row and reuses (a per-ray allocation would cost
as much as the traversal itself).
"""
import math

import numpy as np
from numba import njit

from .geometry import INFO_MAT, INFO_TYPE, intersect_prim
from .layout import MAT_TYPE, NULL

LEAF_SIZE = 4
N_BINS = 12
STACK_SIZE = 64


# ------------------------------------------------------------------------------------------- build
def build(lo: np.ndarray, hi: np.ndarray):
    """Binned-SAH BVH over boxes ``lo``/``hi`` (N x 3). Returns (nodes, node_info, order):
    leaf ranges index the primitives *after* reordering by ``order``."""
    n = len(lo)
    if n == 0:
        raise ValueError("a BVH needs at least one primitive")
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
        split = _sah_split(lo[idx], hi[idx], cen[idx]) if len(idx) > LEAF_SIZE else None
        if split is None:
            order[filled:filled + len(idx)] = idx
            info[k] = (filled, len(idx), 0)
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


def _sah_split(lo, hi, cen):
    """The cheapest binned split (axis, mask of the left side), or None if a leaf is cheaper."""
    n = len(cen)
    clo, chi = cen.min(axis=0), cen.max(axis=0)
    best = (math.inf, None, None)
    for axis in range(3):
        ext = chi[axis] - clo[axis]
        if ext <= 0.0:
            continue
        b = np.minimum((N_BINS * (cen[:, axis] - clo[axis]) / ext).astype(np.int64), N_BINS - 1)
        cnt = np.bincount(b, minlength=N_BINS)
        blo = np.full((N_BINS, 3), np.inf)
        bhi = np.full((N_BINS, 3), -np.inf)
        np.minimum.at(blo, b, lo)
        np.maximum.at(bhi, b, hi)
        for s in range(1, N_BINS):
            nl, nr = cnt[:s].sum(), cnt[s:].sum()
            if nl == 0 or nr == 0:
                continue
            al = _area(bhi[:s].max(0) - blo[:s].min(0))
            ar = _area(bhi[s:].max(0) - blo[s:].min(0))
            cost = al * nl + ar * nr
            if cost < best[0]:
                best = (cost, axis, b < s)
    if best[1] is None:
        if n > 4 * LEAF_SIZE:   # all centroids coincide: split the list in half to bound leaf size
            mask = np.zeros(n, dtype=bool)
            mask[: n // 2] = True
            return 0, mask
        return None
    parent = _area(hi.max(0) - lo.min(0))
    if best[0] >= parent * n and n <= 4 * LEAF_SIZE:   # SAH says a leaf is cheaper (unit costs)
        return None
    return best[1], best[2]


# --------------------------------------------------------------------------------------- traversal
@njit(cache=True, error_model="numpy", inline="always")
def _box_hit(nodes, k, o, inv, tmin, tmax):
    """Slab test of node k; returns the entry distance or inf."""
    t0 = (nodes[k, 0] - o[0]) * inv[0]
    t1 = (nodes[k, 3] - o[0]) * inv[0]
    if t0 > t1:
        t0, t1 = t1, t0
    ty0 = (nodes[k, 1] - o[1]) * inv[1]
    ty1 = (nodes[k, 4] - o[1]) * inv[1]
    if ty0 > ty1:
        ty0, ty1 = ty1, ty0
    tz0 = (nodes[k, 2] - o[2]) * inv[2]
    tz1 = (nodes[k, 5] - o[2]) * inv[2]
    if tz0 > tz1:
        tz0, tz1 = tz1, tz0
    lo = max(max(t0, ty0), max(tz0, tmin))
    hi = min(min(t1, ty1), min(tz1, tmax)) * 1.0000000000000004   # 2 ulp: no leaks at box faces
    if lo <= hi:
        return lo
    return math.inf


@njit(cache=True, error_model="numpy", inline="always")
def _inv_dir(d):
    # 1/0 = +-inf is what the slab test wants; numba raises on float division by zero, so spell it out
    ix = 1.0 / d[0] if d[0] != 0.0 else math.copysign(math.inf, d[0])
    iy = 1.0 / d[1] if d[1] != 0.0 else math.copysign(math.inf, d[1])
    iz = 1.0 / d[2] if d[2] != 0.0 else math.copysign(math.inf, d[2])
    return (ix, iy, iz)


@njit(cache=True, error_model="numpy")
def closest_hit(nodes, node_info, prims, prim_info, o, d, tmin, tmax, stack):
    """(t, prim, u, v) of the nearest hit in (tmin, tmax); prim = -1 on a miss."""
    inv = _inv_dir(d)
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
            for i in range(first, first + count):
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
    inv = _inv_dir(d)
    if _box_hit(nodes, 0, o, inv, tmin, tmax) == math.inf:
        return -1
    sp = 0
    node = 0
    while True:
        first = node_info[node, 0]
        count = node_info[node, 1]
        if count > 0:
            for i in range(first, first + count):
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
