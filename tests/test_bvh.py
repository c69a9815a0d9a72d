"""The BVH traversals against brute force: closest hit and any hit over random rays in a random
soup of triangles, spheres and disks (the answer must be identical, prim for prim)."""
import math

import numpy as np
import pytest

from gdlearn.kernels import geometry as g
from gdlearn.kernels.accel.bvh import STACK_SIZE, any_hit, build_scene, closest_hit
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


def _scene(rows, types, shape_of):
    areas, lo, hi = _bounds(rows, types)
    order, nodes, node_info = build_scene(rows, types, shape_of, lo, hi)
    rows, types = np.ascontiguousarray(rows[order]), types[order]
    info = np.zeros((len(rows), g.INFO_WIDTH), np.int32)
    info[:, g.INFO_TYPE] = types
    info[:, g.INFO_SHAPE] = np.asarray(shape_of)[order]
    return rows, types, info, nodes, node_info


def _brute(rows, types, o, d, tmax):
    best, bp = tmax, -1
    for i in range(len(rows)):
        t, u, v = g.intersect_prim(rows, types[i], i, o, d, 0.0, best)
        if t < best:
            best, bp = t, i
    return best, bp


def _ray(rng, lo, hi):
    d = rng.normal(size=3)
    return tuple(rng.uniform(lo, hi, 3)), tuple(d / np.linalg.norm(d))


def test_closest_and_any_hit_match_brute_force():
    rng = np.random.default_rng(4)
    rows, types = _soup(300, rng)
    rows, types, info, nodes, node_info = _scene(rows, types, np.arange(len(rows)))
    mats = np.zeros((1, MAT_WIDTH))
    stack = np.empty(STACK_SIZE, np.int32)
    # every primitive lies in exactly one leaf
    leaves = node_info[node_info[:, 1] > 0]
    assert sorted(i for f, c, *_ in leaves for i in range(f, f + c)) == list(range(len(rows)))
    # a leaf's triangles come first and are counted (they are tested as one vectorised block)
    for f, c, ntri, _, lanes in leaves:
        assert np.all(types[f:f + ntri] == g.P_TRIANGLE) and np.all(types[f + ntri:f + c] != g.P_TRIANGLE)
        assert lanes == ntri               # no quads in a soup of unrelated triangles
    assert leaves[:, 2].max() > 1          # some blocks test several triangles at once
    hits = 0
    for _ in range(3000):
        o, d = _ray(rng, -7, 7)
        tmax = rng.choice([math.inf, 3.0])
        best, bp = _brute(rows, types, o, d, tmax)
        t, p, u, v = closest_hit(nodes, node_info, rows, info, o, d, 0.0, tmax, stack)
        assert p == bp and (p < 0 or t == best)
        assert (any_hit(nodes, node_info, rows, info, o, d, 0.0, tmax, stack, False, mats) >= 0) == (bp >= 0)
        hits += bp >= 0
    assert hits > 300       # the test exercised hits, not only misses


def test_quads_hit_the_triangle_that_contains_the_point():
    """Rectangles and cube faces (two triangles each, both windings) become one parallelogram lane;
    a hit must still name the triangle of the pair that contains the point, with its barycentrics."""
    from gdlearn.scene.compile import compile_scene
    from gdlearn.scene.load import load
    from pathlib import Path
    sa = compile_scene(load(Path(__file__).resolve().parents[1] / "scenes" / "cornell-box.xml", res=8))
    leaves = sa.node_info[sa.node_info[:, 1] > 0]
    assert leaves[:, 4].sum() * 2 == leaves[:, 2].sum()      # every triangle is half of a quad lane
    rows, types = sa.prims, sa.prim_info[:, g.INFO_TYPE]
    stack = np.empty(STACK_SIZE, np.int32)
    short = np.empty(64, np.int32)
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(4000):
        o, d = _ray(rng, -0.99, 0.99)          # inside the room (open at +z: some rays escape)
        best, bp = _brute(rows, types, o, d, math.inf)
        t, p, u, v = closest_hit(sa.nodes, sa.node_info, rows, sa.prim_info, o, d, 0.0, math.inf, stack)
        assert (p >= 0) == (bp >= 0)
        if p < 0:
            continue
        assert t == pytest.approx(best, rel=1e-12)
        # p may differ from bp only at a tie: an edge, or coplanar faces (a box standing on the floor)
        q = rows[p, 0:3] + u * rows[p, 3:6] + v * rows[p, 6:9]
        assert np.allclose(q, np.array(o) + t * np.array(d), atol=1e-12)
        assert min(u, v) >= -1e-12 and u + v <= 1 + 1e-12
        # a short stack (no room for the lane scratch) gives the same answer by recomputing the lane
        assert closest_hit(sa.nodes, sa.node_info, rows, sa.prim_info, o, d, 0.0, math.inf, short) == (t, p, u, v)
        hits += p == bp
    assert hits > 3000


def test_quad_pairs_are_detected_only_for_parallelograms():
    from gdlearn.kernels.accel.bvh_build import _quad
    p0, a, b = np.zeros(3), np.array([1.0, 0, 0]), np.array([0.3, 1.0, 0])
    tri = lambda e1, e2: np.concatenate([p0, e1, e2, np.zeros(g.PRIM_WIDTH - 9)])     # noqa: E731
    assert _quad(tri(a, a + b), tri(a + b, b)) is not None          # (p0 p1 p2), (p0 p2 p3)
    assert _quad(tri(a + b, a), tri(b, a + b)) is not None          # the other windings
    assert _quad(tri(a, a + b), tri(a + b, 1.1 * b)) is None        # a trapezoid
    assert _quad(tri(a, 0.5 * a + b), tri(0.5 * a + b, b)) is None  # not split along a diagonal


def test_wide_node_slab_tests_match_the_scalar_test_and_come_sorted():
    """simd.children8 tests a wide node's 8 children at once: the children it counts must be those
    the scalar ``bvh._box_hit`` enters, the nearest returned, the others pushed (bvh._push_children,
    simd.sort8) farthest first, each
    key holding its child and its entry distance rounded down. Rays include axis-parallel ones
    (reciprocal direction inf) and origins on a slab (0 * inf = NaN), the boxes flat ones."""
    from numba import njit
    from gdlearn.kernels.accel.bvh import _CHILD, _box_hit, _inv_dir, _push_children, children8
    from gdlearn.kernels.accel.bvh_build import WIDE, WIDE_ROWS

    @njit
    def run(nodes, o, d, tmax, keys, ts):
        inv = _inv_dir(d)
        for c in range(WIDE):
            ts[c] = _box_hit(nodes, 0, c, o, inv, 0.0, tmax) if nodes[6 * WIDE + c] >= 0 else math.inf
        n, near, far = children8(nodes, np.int64(0), o, inv, 0.0, tmax, keys, 3)
        if n > 0:
            _push_children(keys, 3, n, far)
        return n, near

    rng = np.random.default_rng(11)
    keys = np.zeros(16, np.int64)
    ts = np.zeros(WIDE)
    counts = np.zeros(WIDE + 1, int)
    for trial in range(3000):
        block = np.zeros((WIDE_ROWS, WIDE))
        lo = rng.integers(-2, 2, (3, WIDE)).astype(float)
        block[0:3], block[3:6] = lo, lo + rng.choice(4, (3, WIDE), p=[0.1, 0.3, 0.3, 0.3])   # some flat
        block[6] = rng.permutation(100)[:WIDE]
        block[6, rng.random(WIDE) < 0.2] = -1.0                                  # empty lanes
        o = rng.integers(-6, 6, 3).astype(float) + rng.choice([0.0, 0.5], 3)      # on a slab, or not
        d = block[0:3, rng.integers(WIDE)] + 0.5 - o + 0.3 * rng.normal(size=3)   # towards a box, about
        d[rng.random(3) < 0.1] = 0.0                                             # axis-parallel
        if not d.any():
            continue
        tmax = rng.choice([math.inf, 4.0])
        n, near = run(block.reshape(-1), tuple(o), tuple(d / np.linalg.norm(d)), tmax, keys, ts)
        entered = np.flatnonzero(ts < math.inf)
        assert n == len(entered)
        counts[n] += 1
        if n == 0:
            continue
        pushed = list(keys[3:3 + n - 1]) + [near]          # the stack from its bottom, then the nearest
        assert sorted(int(k) & int(_CHILD) for k in pushed) == sorted(block[6, entered].astype(int))
        dist = np.array([np.int64(k & ~_CHILD).view(np.float64) for k in pushed])
        assert np.all(np.diff(dist) <= 0.0)                                     # farthest first
        for k, t in zip(pushed, dist):
            t_exact = max(ts[list(block[6]).index(k & _CHILD)], 0.0)       # (a NaN slab can leave it < 0)
            assert t <= t_exact and (t_exact == 0.0 or t >= t_exact * (1 - 2.0 ** -27))
    assert counts[0] > 100 and counts[2:].sum() > 300 and counts[5:].sum() > 10   # all cases were met


def test_packet_traversal_matches_the_scalar_one():
    """accel.packet.packet_trace over a tree whose leaves hold lanes, spheres and disks: each ray's
    closest primitive and its t, u, v (bits) are the scalar traversal's, its any-hit flag too; idle
    rays (tmax < 0) hit nothing. Leaves are visited in another order than one ray would, which can
    only matter at an exact tie (none in a random soup)."""
    from gdlearn.kernels.accel import packet as PT
    rng = np.random.default_rng(12)
    rows, types = _soup(90, rng)
    rows, types, info, nodes, node_info = _scene(rows, types, np.arange(len(rows)))
    assert node_info[0, 1] == 0 and (node_info[:, 1] > node_info[:, 2]).any()   # a tree; leaves with spheres/disks
    stack = np.empty(STACK_SIZE, np.int32)
    mats = np.zeros((1, MAT_WIDTH))
    ro, pk = PT.N_S_TRACE, PT.PK
    hits = 0
    for _ in range(32):
        S = np.zeros((ro + 7) * pk)
        Q = np.zeros(PT.N_Q_TRACE * pk, dtype=np.int64)
        rays = [(*_ray(rng, -7, 7), rng.choice([math.inf, 3.0, -1.0])) for _ in range(pk)]
        for j, (o, d, tmax) in enumerate(rays):
            S[(ro + np.arange(7)) * pk + j] = (*o, *d, tmax)
        S_any, Q_any = S.copy(), Q.copy()
        PT.packet_trace(nodes, node_info, rows, info, S, Q, ro, stack, False)
        PT.packet_trace(nodes, node_info, rows, info, S_any, Q_any, ro, stack, True)
        for j, (o, d, tmax) in enumerate(rays):
            t, p, u, v = closest_hit(nodes, node_info, rows, info, o, d, 0.0, tmax, stack)
            if tmax < 0.0:
                p = -1
            assert Q[PT.Q_PRIM * pk + j] == p
            if p >= 0:
                assert (S[(ro + 6) * pk + j], S[PT.S_U * pk + j], S[PT.S_V * pk + j]) == (t, u, v)
                hits += types[p] != g.P_TRIANGLE
            blocked = tmax > 0.0 and any_hit(nodes, node_info, rows, info, o, d, 0.0, tmax, stack, False, mats) >= 0
            assert Q_any[PT.Q_HIT * pk + j] == blocked
    assert hits > 20        # spheres and disks were hit, not only lanes


@pytest.mark.parametrize("keep", [True, False])
def test_every_lane_of_a_leaf_is_tested_whatever_its_size(keep):
    """_leaf_lanes on leaves of 1 to 20 lanes: 8-lane blocks, and a last block of at most 4 lanes
    tested 4 wide (simd.block4). Lane k is a triangle at x in [k, k + 0.5], z = -k / 10: a ray
    straight down onto it finds lane k at t = 1 + k / 10 (kept in the scratch); a ray past the
    last lane finds none. A lane left out of its block (a 4-wide test of 5 lanes) fails."""
    from gdlearn.kernels.accel.bvh import _SCRATCH, _leaf_lanes
    from gdlearn.kernels.accel.bvh_build import LANES, ROW_LIM, SOA_ROWS
    scratch = np.zeros(3 * _SCRATCH)
    for lanes in range(1, 21):
        n8 = -(-lanes // LANES) * LANES
        block = np.zeros((SOA_ROWS, n8))
        for k in range(lanes):
            block[0:3, k] = (k, 0.0, -k / 10)
            block[3:6, k] = (0.5, 0.0, 0.0)
            block[6:9, k] = (0.0, 0.5, 0.0)
            block[ROW_LIM, k] = 1.0
        nodes = np.concatenate([np.full(5, np.nan), block.reshape(-1)])     # the leaf's block at base 5
        for k in range(lanes):
            got = _leaf_lanes(nodes, 5, lanes, (k + 0.1, 0.1, 1.0), (0.0, 0.0, -1.0), 0.0, math.inf, scratch, keep)
            assert got == k, (lanes, k)
            if keep:
                assert scratch[k] == 1.0 + k / 10
        assert _leaf_lanes(nodes, 5, lanes, (lanes + 0.7, 0.1, 1.0), (0.0, 0.0, -1.0), 0.0, math.inf,
                           scratch, keep) == -1
