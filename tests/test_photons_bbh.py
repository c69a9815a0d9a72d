"""The bounding-box hierarchy returns exactly the photons whose disc or ball a ray segment crosses
(gdlearn.photons.bbh; Jarosz et al. 2008, Alg. 1), compared with a brute-force numpy evaluation
of the same definition."""
import math

import numpy as np
import pytest

from gdlearn.photons import bbh as B


def _brute(pos, r, o, d, tmax, mode):
    q = pos - o
    tp = q @ d
    perp = q - tp[:, None] * d
    dp2 = (perp ** 2).sum(axis=1)
    inside = dp2 < r * r
    if mode == 2:
        ok = inside & (tp > 0) & (tp < tmax)
    else:
        half = np.sqrt(np.where(inside, r * r - dp2, 0.0))
        ok = inside & (tp + half > 0) & (tp - half < tmax)
    return set(np.flatnonzero(ok).tolist())


def _collect(tree, o, d, tmax, mode):
    out = np.empty(len(tree.order) + 1, dtype=np.int64)
    n = B.collect(tree, np.asarray(o, float), np.asarray(d, float), float(tmax), mode, out)
    ids = out[:n].tolist()
    assert len(ids) == len(set(ids)), "a photon was reported twice"
    return set(ids)


def _clouds(kind, rng):
    if kind == "uniform":
        pos = rng.uniform(-1, 1, (3000, 3))
    else:       # a few dense blobs and a sparse background
        centres = rng.uniform(-1, 1, (4, 3))
        pos = np.concatenate([c + 0.05 * rng.normal(size=(600, 3)) for c in centres] + [rng.uniform(-1, 1, (400, 3))])
    r = np.exp(rng.normal(math.log(0.03), 1.2, len(pos)))        # radii over ~2 decades
    return pos, r


def _rays(rng, count):
    for k in range(count):
        o = rng.uniform(-1.3, 1.3, 3)
        d = rng.normal(size=3)
        if k % 4 == 0:                       # parallel to an axis or a coordinate plane: zero components
            d[rng.integers(3)] = 0.0
            if k % 8 == 0:
                d[rng.integers(3)] = 0.0
        if not np.any(d):
            d[0] = 1.0
        d /= np.linalg.norm(d)
        yield o, d, (math.inf if k % 2 else rng.uniform(0.05, 2.0))


@pytest.mark.parametrize("leaf", [1, 4, 8])
@pytest.mark.parametrize("kind", ["uniform", "clustered"])
def test_collect_equals_brute_force(kind, leaf):
    rng = np.random.default_rng(11 if kind == "uniform" else 12)
    pos, r = _clouds(kind, rng)
    tree = B.build(pos, r, leaf)
    hits = 0
    for o, d, tmax in _rays(rng, 120):
        for mode in (2, 3):
            want = _brute(pos, r, o, d, tmax, mode)
            assert _collect(tree, o, d, tmax, mode) == want, (o, d, tmax, mode)
            hits += len(want)
    assert hits > 1000       # the rays do meet photons: the comparison is not vacuous


def test_structure_every_photon_once_and_boxes_hold_their_spheres():
    rng = np.random.default_rng(5)
    pos, r = _clouds("clustered", rng)
    t = B.build(pos, r, 4)
    assert sorted(t.order.tolist()) == list(range(len(pos)))
    np.testing.assert_array_equal(t.pos, pos[t.order])
    for node in range(len(t.right)):
        if t.left[node] < 0:
            sl = slice(t.start[node], t.start[node] + t.count[node])
            assert np.all(t.pos[sl] - t.radius[sl, None] >= t.lo[node])
            assert np.all(t.pos[sl] + t.radius[sl, None] <= t.hi[node])
        else:
            for c in (t.left[node], t.right[node]):
                assert c > node and np.all(t.lo[c] >= t.lo[node]) and np.all(t.hi[c] <= t.hi[node])


def test_far_photons_keep_the_perpendicular_distance_exact():
    # photons 1e6 from the ray origin with radius 1e-3: |c - o|^2 - t_p^2 would lose every digit
    rng = np.random.default_rng(2)
    n = 400
    t_along = rng.uniform(0.5e6, 1.5e6, n)
    off = rng.uniform(-2e-3, 2e-3, (n, 2))
    d = np.array([1.0, 2.0, 2.0]) / 3.0
    u = np.array([2.0, -1.0, 0.0]) / math.sqrt(5)
    w = np.cross(d, u)
    pos = t_along[:, None] * d + off[:, :1] * u + off[:, 1:] * w
    r = np.full(n, 1e-3)
    tree = B.build(pos, r)
    got = _collect(tree, np.zeros(3), d, math.inf, 2)
    want = set(np.flatnonzero((off ** 2).sum(axis=1) < 1e-6).tolist())
    assert got == want and 0 < len(want) < n


def test_empty_and_single_photon():
    empty = B.build(np.zeros((0, 3)), np.zeros(0))
    assert _collect(empty, (0, 0, 0), (1, 0, 0), math.inf, 3) == set()
    one = B.build(np.array([[1.0, 0.05, 0.0]]), 0.1)
    assert _collect(one, (0, 0, 0), (1, 0, 0), math.inf, 2) == {0}
    assert _collect(one, (0, 0, 0), (1, 0, 0), 0.5, 2) == set()      # t_p = 1 beyond the segment
    assert _collect(one, (0, 0, 0), (1, 0, 0), 0.95, 3) == {0}       # the ball's chord reaches 0.95
    assert _collect(one, (0, 0, 0), (-1, 0, 0), math.inf, 3) == set()


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="radii"):
        B.build(np.zeros((2, 3)), np.array([0.1, 0.0]))
