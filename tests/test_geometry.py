"""Ray-primitive intersection, surface interactions and emitter sampling against independent maths.

Random rays are checked against closed-form plane / sphere solutions written here with numpy (not
the kernels); the emitter sampler's pdf is checked for consistency with emitter_pdf and its
uniform-area claim by the mean of sampled points (the centroid), within 5 standard errors.
"""
import math

import numpy as np
import pytest

from gdlearn.kernels import geometry as g
from gdlearn.kernels.lights import prim_point
from gdlearn.scene.compile import _shape_prims
from gdlearn.scene.model import Shape

RNG = np.random.default_rng(1)


def _unit(v):
    return v / np.linalg.norm(v)


def _tri(a, b, c):
    row = np.zeros(g.PRIM_WIDTH)
    a, b, c = map(np.asarray, (a, b, c))
    row[0:3], row[3:6], row[6:9] = a, b - a, c - a
    row[9:12] = _unit(np.cross(b - a, c - a))
    return row


def test_triangle_hits_match_barycentric_solution():
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
    row = _tri(a, b, c)
    for _ in range(2000):
        o = RNG.normal(size=3) * 2 + np.array([0, 0, 3])
        target = RNG.uniform(-0.5, 1.5, size=2)
        p = np.array([target[0], target[1], 0.0])
        d = _unit(p - o)
        t, u, v = g.intersect_triangle(row[None], 0, tuple(o), tuple(d), math.inf)
        inside = p[0] >= 0 and p[1] >= 0 and p[0] + p[1] <= 1
        margin = min(p[0], p[1], 1 - p[0] - p[1])
        if abs(margin) < 1e-9:
            continue                 # on an edge: either answer is right
        assert (t < math.inf) == inside
        if inside:
            assert t == pytest.approx(np.linalg.norm(p - o), rel=1e-12)
            assert (u, v) == pytest.approx((p[0], p[1]), abs=1e-12)


def test_sphere_hits_from_outside_and_inside():
    row = np.zeros(g.PRIM_WIDTH)
    c, r = np.array([0.3, -0.2, 1.0]), 0.7
    row[0:3], row[g.G_R], row[g.G_SIGN] = c, r, 1.0
    for _ in range(2000):
        o = c + RNG.normal(size=3) * 1.5
        d = _unit(RNG.normal(size=3))
        # independent: solve |o + t d - c|^2 = r^2 with numpy's polynomial roots
        roots = np.roots([1.0, 2 * d @ (o - c), (o - c) @ (o - c) - r * r])
        roots = sorted(x.real for x in roots if abs(x.imag) < 1e-12 and x.real > 1e-9)
        t = g.intersect_sphere(row[None], 0, tuple(o), tuple(d), 1e-9, math.inf)
        if roots:
            assert t == pytest.approx(roots[0], rel=1e-9, abs=1e-12)
        else:
            assert t == math.inf


def test_disk_accepts_inside_of_an_ellipse():
    sh = Shape("disk", np.diag([2.0, 0.5, 1.0, 1.0]))
    rows, types, areas, lo, hi = _shape_prims(sh)
    assert areas[0] == pytest.approx(math.pi * 2.0 * 0.5)
    for _ in range(1000):
        x, y = RNG.uniform(-2.5, 2.5), RNG.uniform(-0.8, 0.8)
        o, d = (x, y, 2.0), (0.0, 0.0, -1.0)
        t, u, v = g.intersect_disk(rows, 0, o, d, math.inf)
        assert (t < math.inf) == ((x / 2) ** 2 + (y / 0.5) ** 2 <= 1.0)


def test_rectangle_normal_follows_mitsuba_and_flip():
    # rotate +90 degrees about x: Mitsuba's rectangle normal (0, 0, 1) becomes (0, -1, 0)
    rot = np.eye(4)
    rot[1:3, 1:3] = [[0, -1], [1, 0]]
    rows, *_ = _shape_prims(Shape("rectangle", rot))
    for r in rows:
        assert r[9:12] == pytest.approx([0, -1, 0])
        assert np.cross(r[3:6], r[6:9]) @ r[9:12] > 0       # winding agrees with the stored normal
    rows, *_ = _shape_prims(Shape("rectangle", rot, flip_normals=True))
    assert rows[0][9:12] == pytest.approx([0, 1, 0])


def test_cube_is_closed_with_outward_normals():
    rows, types, areas, lo, hi = _shape_prims(Shape("cube", np.diag([1.0, 2.0, 3.0, 1.0])))
    assert len(rows) == 12 and areas.sum() == pytest.approx(2 * (2 * 4 + 4 * 6 + 2 * 6))
    for r in rows:
        centroid = r[0:3] + (r[3:6] + r[6:9]) / 3
        assert centroid @ r[9:12] > 0


@pytest.mark.parametrize("kind", ["triangle", "sphere", "disk"])
def test_uniform_points_have_the_centroid_as_mean(kind):
    if kind == "triangle":
        rows = np.array([_tri([0, 0, 0], [2, 0, 0], [0, 1, 1])])
        info = np.zeros((1, g.INFO_WIDTH), np.int32)
        want = np.array([2 / 3, 1 / 3, 1 / 3])
    elif kind == "sphere":
        rows, *_ = _shape_prims(Shape("sphere", np.diag([0.5, 0.5, 0.5, 1.0])))
        info = np.full((1, g.INFO_WIDTH), g.P_SPHERE, np.int32)
        want = np.zeros(3)
    else:
        m = np.eye(4)
        m[:3, 3] = (1, 2, 3)
        rows, *_ = _shape_prims(Shape("disk", m))
        info = np.full((1, g.INFO_WIDTH), g.P_DISK, np.int32)
        want = np.array([1.0, 2, 3])
    u = RNG.random((20000, 2))
    pts = np.array([prim_point(rows, info, 0, a, b)[0] for a, b in u])
    se = pts.std(0) / math.sqrt(len(pts))
    assert np.all(np.abs(pts.mean(0) - want) < 5 * se + 1e-12)
    if kind == "sphere":   # also the first moment of |z| of a uniform sphere point: r / 2
        assert abs(np.abs(pts[:, 2]).mean() - 0.25) < 5 * np.abs(pts[:, 2]).std() / math.sqrt(len(pts))
