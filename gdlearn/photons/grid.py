"""A hashed uniform grid for fixed-radius range queries over photons, rebuilt every pass.

The spatial hash of Teschner et al. 2003 ("Optimized Spatial Hashing for Collision Detection of
Deformable Objects", the three primes) as pbrt-v3's SPPM uses it, but with the photons -- not the
gather points -- in the grid, and built by a counting sort on the bucket: ``order`` lists the point
ids bucket by bucket (ids ascending inside a bucket: the build is deterministic), ``start[b] ..
start[b + 1]`` is bucket b's range. A query visits every cell that overlaps the box [p - r, p + r],
so any radius works (larger than a cell, too); a point is accepted only if its own cell is the
visited cell (two cells may share a bucket: without the check a point could be counted twice)
and its distance is < r (the uniform disc/ball kernel of PHOTONS.md Sec. 1.3, test ``d < r``).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from gdlearn.kernels.jit import block, inlined


_P1, _P2, _P3 = 73856093, 19349663, 83492791


class HashGrid(NamedTuple):
    pos: np.ndarray       # f64 (n, 3): the points, in bucket order
    cell: np.ndarray      # i64 (n, 3): their integer cells, in bucket order
    order: np.ndarray     # i64 (n,): original id of each bucket-ordered point
    start: np.ndarray     # i64 (T + 1,): bucket ranges into order
    inv_h: float          # 1 / cell size
    mask: int             # T - 1 (T a power of two)


@inlined
def bucket(ix, iy, iz, mask):
    return ((ix * _P1) ^ (iy * _P2) ^ (iz * _P3)) & mask


@inlined
def cell_of(x, inv_h):
    return int(math.floor(x * inv_h))


@block
def _build(pts, inv_h, mask, pos, cell, order, start):
    n = pts.shape[0]
    b = np.empty(n, dtype=np.int64)
    c = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for k in range(3):
            c[i, k] = cell_of(pts[i, k], inv_h)
        b[i] = bucket(c[i, 0], c[i, 1], c[i, 2], mask)
        start[b[i] + 1] += 1
    for t in range(mask + 1):
        start[t + 1] += start[t]
    fill = start[:-1].copy()
    for i in range(n):          # ascending ids: a stable counting sort
        s = fill[b[i]]
        fill[b[i]] += 1
        order[s] = i
        for k in range(3):
            pos[s, k] = pts[i, k]
            cell[s, k] = c[i, k]


def build(points: np.ndarray, cell_size: float) -> HashGrid:
    """The grid of ``points`` (n x 3) with cells of ``cell_size`` (> 0; the typical query radius)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if not (cell_size > 0 and math.isfinite(cell_size)):
        raise ValueError(f"cell_size must be a positive finite number, not {cell_size!r}")
    n = pts.shape[0]
    t = 1 << max(1, int(2 * n - 1).bit_length())        # >= 2n buckets: few collisions
    grid = HashGrid(np.empty((n, 3)), np.empty((n, 3), np.int64), np.empty(n, np.int64),
                    np.zeros(t + 1, np.int64), 1.0 / float(cell_size), t - 1)
    _build(pts, grid.inv_h, grid.mask, grid.pos, grid.cell, grid.order, grid.start)
    return grid


def build_rows(pos: np.ndarray, rows: np.ndarray, cell_size: float) -> HashGrid:
    """The grid of the points ``pos[rows]`` whose queries answer ``rows`` (light-vertex rows), not
    positions in the subset."""
    g = build(pos[rows], cell_size)
    return g._replace(order=rows[g.order])


@block
def query(grid, p, r, out):
    """Original ids of the points with |x - p| < r into ``out`` (in visiting order); returns how
    many there are (at most len(out) are written). The loop is the pattern the gather kernels use."""
    n = 0
    r2 = r * r
    lo = (cell_of(p[0] - r, grid.inv_h), cell_of(p[1] - r, grid.inv_h), cell_of(p[2] - r, grid.inv_h))
    hi = (cell_of(p[0] + r, grid.inv_h), cell_of(p[1] + r, grid.inv_h), cell_of(p[2] + r, grid.inv_h))
    for ix in range(lo[0], hi[0] + 1):
        for iy in range(lo[1], hi[1] + 1):
            for iz in range(lo[2], hi[2] + 1):
                b = bucket(ix, iy, iz, grid.mask)
                for s in range(grid.start[b], grid.start[b + 1]):
                    if grid.cell[s, 0] != ix or grid.cell[s, 1] != iy or grid.cell[s, 2] != iz:
                        continue
                    dx = grid.pos[s, 0] - p[0]
                    dy = grid.pos[s, 1] - p[1]
                    dz = grid.pos[s, 2] - p[2]
                    if dx * dx + dy * dy + dz * dz < r2:
                        if n < out.shape[0]:
                            out[n] = grid.order[s]
                        n += 1
    return n
