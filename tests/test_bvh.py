"""The BVH traversals against brute force: closest hit and any hit over random rays in a random
soup of triangles, spheres and disks (the answer must be identical, prim for prim)."""
import math

import numpy as np

from gdlearn.kernels import geometry as g
from gdlearn.kernels.bvh import STACK_SIZE, any_hit, build, closest_hit, pack
from gdlearn.scene.compile import _bounds
from gdlearn.kernels.layout import MAT_WIDTH


def _soup(n, rng):
    rows, types = [], []
    for i in range(n):
        c = rng.uniform(-5, 5, 3)
        row = np.zeros(g.PRIM_WIDTH)
        k = i % 3
        if k == 0:
            a, b = rng.normal(size=3) * 0.6, rng.normal(size=3) * 0.6
            row[0:3], row[3:6], row[6:9] = c, a, b
            row[9:12] = np.cross(a, b) / np.linalg.norm(np.cross(a, b))
        elif k == 1:
            row[0:3], row[g.G_R], row[g.G_SIGN] = c, rng.uniform(0.1, 0.5), 1.0
        else:
            a, b = rng.normal(size=3) * 0.4, rng.normal(size=3) * 0.4
            n_ = np.cross(a, b)
            row[0:3], row[3:6], row[6:9], row[9:12] = c, a, b, n_ / np.linalg.norm(n_)
            gram = np.linalg.inv(np.array([[a @ a, a @ b], [a @ b, b @ b]]))
            row[12:15], row[15:18] = gram[0, 0] * a + gram[0, 1] * b, gram[1, 0] * a + gram[1, 1] * b
        rows.append(row)
        types.append(k)
    return np.array(rows), np.array(types, np.int32)


def test_closest_and_any_hit_match_brute_force():
    rng = np.random.default_rng(4)
    rows, types = _soup(300, rng)
    areas, lo, hi = _bounds(rows, types)
    boxes, tree, order = build(lo, hi, types)
    rows, types = np.ascontiguousarray(rows[order]), types[order]
    nodes, node_info = pack(boxes, tree, rows)
    info = np.zeros((len(rows), g.INFO_WIDTH), np.int32)
    info[:, g.INFO_TYPE] = types
    mats = np.zeros((1, MAT_WIDTH))
    stack = np.empty(STACK_SIZE, np.int32)
    # every primitive lies in exactly one leaf
    leaves = node_info[node_info[:, 1] > 0]
    assert sorted(i for f, c, _, _ in leaves for i in range(f, f + c)) == list(range(len(rows)))
    # a leaf's triangles come first and are counted (they are tested as one vectorised block)
    for f, c, ntri, _ in leaves:
        assert np.all(types[f:f + ntri] == g.P_TRIANGLE) and np.all(types[f + ntri:f + c] != g.P_TRIANGLE)
    assert leaves[:, 2].max() > 1          # some blocks test several triangles at once
    hits = 0
    for _ in range(3000):
        o = tuple(rng.uniform(-7, 7, 3))
        d = rng.normal(size=3)
        d = tuple(d / np.linalg.norm(d))
        tmax = rng.choice([math.inf, 3.0])
        best, bp = tmax, -1
        for i in range(len(rows)):
            t, u, v = g.intersect_prim(rows, types[i], i, o, d, 0.0, best)
            if t < best:
                best, bp = t, i
        t, p, u, v = closest_hit(nodes, node_info, rows, info, o, d, 0.0, tmax, stack)
        assert p == bp and (p < 0 or t == best)
        assert (any_hit(nodes, node_info, rows, info, o, d, 0.0, tmax, stack, False, mats) >= 0) == (bp >= 0)
        hits += bp >= 0
    assert hits > 300       # the test exercised hits, not only misses
