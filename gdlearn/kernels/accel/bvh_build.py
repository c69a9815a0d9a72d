"""Building the BVH of :mod:`gdlearn.kernels.accel.bvh` (Python + numpy, once per scene).

Binned surface-area heuristic (Wald 2007, "On fast construction of SAH-based bounding volume
hierarchies"), ``N_BINS`` bins per axis, with the costs of the traversal measured on this machine
(``C_*``, benchmarks/bench_pt_traversal.py --sweep), leaves of at most ``LEAF_MAX`` items.

The BVH is built over *items*: a triangle, a *quad* -- two consecutive triangles of one shape that
share their first vertex and their diagonal and together form a parallelogram (every rectangle and
cube face, and many quad meshes) -- or a sphere / disk. Triangles and quads become *lanes* of a
leaf's block, tested all at once by a vectorised loop; a quad costs one lane instead of two (the
Cornell box: 18 lanes instead of 36). The primitives are then reordered so that every leaf is a
contiguous range, its lane primitives first and a quad's two triangles adjacent, and the binary
tree is collapsed into a wide one (:func:`_collapse`).

A lane stores p0, e1, e2 (a triangle's edges, or a parallelogram's sides E1, E3), the bound ``lim``
of a + b (1 for a triangle, 2 for a parallelogram) and ``meta`` = 8 * (rank of its first primitive
in the leaf) + kind bits: 1 quad, 2 "triangle A's e1 is the diagonal", 4 "triangle B's e1 is the
diagonal" (``bvh._lane_prim`` maps a parallelogram hit (a, b) back to A or B and its barycentrics).
"""
import math

import numpy as np

from gdlearn.kernels.accel.forms import mark_form
from gdlearn.kernels.geometry import P_TRIANGLE

N_BINS = 12
#: SAH costs in units of one lane of a vectorised leaf, measured on this machine with
#: benchmarks/bench_pt_traversal.py --sweep: a level of the binary tree (once collapsed, an eighth
#: to a third of a wide node's slab test and sort; 8 measured best on the mesh scene, and keeps the
#: small scenes one leaf), starting a leaf, testing a sphere or disk (scalar). A leaf holds at most
#: LEAF_MAX items (a lane's index must fit the 8 low bits of a nearest-hit key).
C_NODE = 8.0
C_LEAF = 2.0
C_LANE = 1.0
C_PRIM = 6.0
LEAF_MAX = 64
#: lanes per block row: a multiple of the SIMD width (8 float64 with AVX-512)
LANES = 8
#: children of a wide interior node, tested at once (``simd.children8``); its block's rows
WIDE = 8
WIDE_ROWS = 7
#: low bits of a traversal's child key that hold the child's node index (the rest: its entry
#: distance's bits, ``simd.children8``)
CHILD_BITS = 24
CHILD_MASK = (1 << CHILD_BITS) - 1
#: the traversal's stack of child keys (``bvh.KEYS``; a wide node pushes at most WIDE - 1 and
#: writes 9 keys from the top)
STACK_KEYS = 256
SOA_ROWS = 11
ROW_LIM, ROW_META = 9, 10
K_QUAD, K_A_DIAG, K_B_DIAG = 1, 2, 4


def build(lo: np.ndarray, hi: np.ndarray, kinds: np.ndarray | None = None):
    """Binned-SAH BVH over item boxes ``lo``/``hi`` (N x 3); ``kinds == P_TRIANGLE`` marks lane
    items (None: no lanes). Returns (boxes (M x 6), info (M x 3), order): a leaf's info is (first,
    count, lanes) over the items *reordered by* ``order``, lane items first; an interior node's is
    (first child, 0, split axis), its children ``first`` and ``first + 1``."""
    n = len(lo)
    if n == 0:
        raise ValueError("a BVH needs at least one primitive")
    lane = np.zeros(n, dtype=bool) if kinds is None else (np.asarray(kinds) == P_TRIANGLE)
    cost = np.where(lane, C_LANE, C_PRIM)
    cen = 0.5 * (lo + hi)
    nodes, info = [None], [None]
    order = np.empty(n, dtype=np.int64)
    filled = 0
    work = [(0, np.arange(n))]              # explicit work list: (node index, item indices)
    while work:
        k, idx = work.pop()
        nodes[k] = np.concatenate([lo[idx].min(axis=0), hi[idx].max(axis=0)])
        split = _sah_split(lo[idx], hi[idx], cen[idx], cost[idx]) if len(idx) > 2 else None
        if split is None:
            idx = idx[np.argsort(~lane[idx], kind="stable")]         # lanes first
            order[filled:filled + len(idx)] = idx
            info[k] = (filled, len(idx), int(lane[idx].sum()))
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


def _quad(ra, rb):
    """(p0, E1, E3, kind) if triangle rows ra, rb (p0, e1, e2) form a parallelogram split along a
    shared diagonal from a shared first vertex, else None."""
    if not np.array_equal(ra[0:3], rb[0:3]):
        return None
    ea, eb = (ra[3:6], ra[6:9]), (rb[3:6], rb[6:9])
    for ia in range(2):
        for ib in range(2):
            d = ea[ia]
            if not np.array_equal(d, eb[ib]):
                continue
            e1, e3 = ea[1 - ia], eb[1 - ib]
            cr = np.linalg.norm(np.cross(e1, e3))
            if cr > 0.0 and np.linalg.norm(d - (e1 + e3)) <= 1e-12 * np.linalg.norm(d):
                return ra[0:3], e1, e3, K_QUAD | (K_A_DIAG if ia == 0 else 0) | (K_B_DIAG if ib == 0 else 0)
    return None


def _items(rows, types, shape_of):
    """[(primitive indices, lane or None)]: quads from consecutive triangle pairs of one shape."""
    items, i, n = [], 0, len(rows)
    while i < n:
        if types[i] == P_TRIANGLE:
            if i + 1 < n and types[i + 1] == P_TRIANGLE and shape_of[i] == shape_of[i + 1]:
                q = _quad(rows[i], rows[i + 1])
                if q is not None:
                    items.append(((i, i + 1), q))
                    i += 2
                    continue
            items.append(((i,), (rows[i, 0:3], rows[i, 3:6], rows[i, 6:9], 0)))
        else:
            items.append(((i,), None))
        i += 1
    return items


def _collapse(boxes, info):
    """The binary tree as a wide one: (rows, children) -- binary nodes in depth-first order, root
    first, each interior one with its WIDE or fewer children: its two, then repeatedly the two of
    its interior child of the largest surface area (Wald et al. 2008, "Getting rid of packets")."""
    rows, children, depth = [], {}, {0: 1}
    work = [0]
    while work:
        b = work.pop()
        rows.append(b)
        if info[b, 1] > 0:
            continue
        kids = [int(info[b, 0]), int(info[b, 0]) + 1]
        while len(kids) < WIDE:
            inner = [c for c in kids if info[c, 1] == 0]
            if not inner:
                break
            c = max(inner, key=lambda c: _area(boxes[c, 3:6] - boxes[c, 0:3]))
            i = kids.index(c)
            kids[i:i + 1] = [int(info[c, 0]), int(info[c, 0]) + 1]
        children[b] = kids
        for c in kids:
            depth[c] = depth[b] + 1
        work.extend(reversed(kids))
    if (WIDE - 1) * max(depth.values()) + WIDE + 1 > STACK_KEYS:      # a push writes 9 past the top
        raise ValueError(f"the BVH is {max(depth.values())} levels deep: more than the traversal's stack "
                         f"(bvh.KEYS = {STACK_KEYS} keys) can hold; raise bvh_build.STACK_KEYS and bvh.KEYS")
    return rows, children


def _wide_block(boxes, kids, row_of):
    """A wide node's block: its children's box minima and maxima and node indices, WIDE lanes per
    row (empty lanes: index -1, never entered)."""
    block = np.zeros((WIDE_ROWS, WIDE))
    block[6, :] = -1.0
    for j, c in enumerate(kids):
        block[0:6, j] = boxes[c]
        block[6, j] = row_of[c]
    return block


def build_scene(rows, types, shape_of, lo, hi):
    """The traversal's arrays for primitive rows ``rows`` (geometry layout) of types ``types`` from
    shapes ``shape_of``, with boxes lo/hi: returns (order, nodes, node_info) -- apply ``order`` to
    every per-primitive array (see :mod:`gdlearn.kernels.accel.bvh` for the layout). ``node_info``
    is read-only when the tree is one leaf (:mod:`gdlearn.kernels.accel.forms`)."""
    items = _items(rows, types, shape_of)
    ilo = np.array([lo[list(p)].min(0) for p, _ in items])
    ihi = np.array([hi[list(p)].max(0) for p, _ in items])
    kinds = np.array([P_TRIANGLE if lane is not None else -1 for _, lane in items])
    boxes, info, iorder = build(ilo, ihi, kinds)
    sizes = np.array([len(items[k][0]) for k in iorder])
    offs = np.concatenate([[0], np.cumsum(sizes)])
    order = np.array([p for k in iorder for p in items[k][0]], dtype=np.int64)
    wide, children = _collapse(boxes, info)
    if len(wide) > CHILD_MASK:
        raise ValueError(f"{len(wide)} BVH nodes: a child key holds at most {CHILD_MASK} (bvh_build.CHILD_BITS)")
    row_of = {b: r for r, b in enumerate(wide)}
    node_info = np.zeros((len(wide), 5), dtype=np.int32)
    parts, off = [], 0
    for r, k in enumerate(wide):
        first, count, nl = (int(x) for x in info[k])
        if count == 0:
            node_info[r, 0], node_info[r, 2] = off, len(children[k])
            parts.append(_wide_block(boxes, children[k], row_of).reshape(-1))
            off += WIDE_ROWS * WIDE
            continue
        node_info[r, :3] = offs[first], offs[first + count] - offs[first], offs[first + nl] - offs[first]
        if nl == 0:
            continue
        n8 = -(-nl // LANES) * LANES
        block = np.zeros((SOA_ROWS, n8))     # padding lanes: zero edges, det = 0, never hit
        for j in range(nl):
            p0, e1, e2, kind = items[iorder[first + j]][1]
            block[0:3, j], block[3:6, j], block[6:9, j] = p0, e1, e2
            block[ROW_LIM, j] = 2.0 if kind & K_QUAD else 1.0
            block[ROW_META, j] = 8 * (offs[first + j] - offs[first]) + kind
        node_info[r, 3], node_info[r, 4] = off, nl
        parts.append(block.reshape(-1))
        off += block.size
    nodes = np.concatenate(parts) if parts else np.zeros(0)
    return order, np.ascontiguousarray(nodes), mark_form(node_info)
