"""The hash grid's fixed-radius range queries equal a brute-force search (gdlearn.photons.grid)."""
import numpy as np
import pytest

from gdlearn.photons import grid as G


def _brute(pts, p, r):
    d2 = ((pts - p) ** 2).sum(axis=1)
    return set(np.flatnonzero(d2 < r * r).tolist())


def _query(g, p, r, cap=100000):
    out = np.empty(cap, dtype=np.int64)
    n = G.query(g, np.asarray(p, dtype=np.float64), float(r), out)
    ids = out[:n].tolist()
    assert len(ids) == len(set(ids)), "a point was reported twice (bucket collision not checked)"
    return set(ids)


@pytest.mark.parametrize("cell,radius", [(0.1, 0.05), (0.1, 0.1), (0.05, 0.37), (1.0, 0.02)])
def test_random_points_match_brute_force(cell, radius):
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1, 1, size=(3000, 3))
    g = G.build(pts, cell)
    for p in rng.uniform(-1.2, 1.2, size=(60, 3)):
        assert _query(g, p, radius) == _brute(pts, p, radius)


def test_points_on_cell_boundaries_and_negative_coordinates():
    # a lattice exactly on the cell corners (multiples of h): floor() decides the cell, and the
    # query box [p - r, p + r] must still reach the neighbouring cells
    h = 0.25
    ax = np.arange(-4, 5) * h
    pts = np.array(np.meshgrid(ax, ax, ax)).reshape(3, -1).T.copy()
    g = G.build(pts, h)
    for p in [(0.0, 0.0, 0.0), (-0.25, 0.5, 0.75), (0.125, 0.125, 0.125), (-1.0, -1.0, -1.0)]:
        for r in (0.25, 0.2500001, 0.3, 0.6):
            assert _query(g, p, r) == _brute(pts, np.array(p), r)


def test_empty_grid_and_empty_result():
    g = G.build(np.zeros((0, 3)), 0.1)
    assert _query(g, (0, 0, 0), 1.0) == set()
    g = G.build(np.array([[5.0, 5.0, 5.0]]), 0.1)
    assert _query(g, (0, 0, 0), 1.0) == set()
    assert _query(g, (5, 5, 5.05), 0.1) == {0}


def test_query_can_fail_without_the_cell_check():
    """Many cells of a small table collide; a query spanning them must still count each point once
    (the check that fails when the grid forgets its per-point cell test)."""
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1, 1, size=(8, 3))
    g = G.build(pts, 0.05)          # 16 buckets, r spans ~80^3 cells: every bucket visited often
    assert _query(g, (0, 0, 0), 2.0) == _brute(pts, np.zeros(3), 2.0)


def test_bad_cell_size_is_refused():
    with pytest.raises(ValueError):
        G.build(np.zeros((1, 3)), 0.0)
