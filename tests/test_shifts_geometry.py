"""Synthetic geometry for the shift-mapping tests (planes and spheres in numpy), the finite-difference
Jacobian of a map between 2-D charts, and tests of these helpers themselves.

The shift tests differentiate the shift map *itself*: a base path's free coordinate (a vertex moved
on its surface in a 2-D chart, or a direction moved on the unit sphere) is perturbed, the offset path
is recomputed by ray tracing these surfaces, and the offset's coordinate is read in a chart at the
offset point. Every chart used here has an orthonormal derivative at the point of expansion, so the
determinant of the 2x2 finite-difference matrix is the Jacobian in the area / solid-angle measure.

The harness (charts, fourth-order central differences, step and error analysis) is
:mod:`gdlearn.testing.fdjac`, shared with the exercises' checks and the book's figures.
"""
import numpy as np

from gdlearn.testing.fdjac import H, direction_chart, fd_jacobian_at_point as fd_jacobian, tangent_frame, unit  # noqa: E402,F401


class Plane:
    def __init__(self, point, normal):
        self.p = np.asarray(point, float)
        self.n = unit(normal)

    def intersect(self, o, d):
        den = np.dot(d, self.n)
        if abs(den) < 1e-300:
            return np.nan
        t = np.dot(self.p - o, self.n) / den
        return t if t > 1e-9 else np.nan

    def normal(self, x):
        return self.n

    def chart(self, x0, u, v):
        e1, e2 = tangent_frame(self.n)
        return x0 + u * e1 + v * e2


class Sphere:
    def __init__(self, center, radius):
        self.c = np.asarray(center, float)
        self.r = float(radius)

    def intersect(self, o, d):
        oc = o - self.c
        b = np.dot(oc, d)
        disc = b * b - (np.dot(oc, oc) - self.r * self.r)
        if disc < 0:
            return np.nan
        s = np.sqrt(disc)
        for t in (-b - s, -b + s):
            if t > 1e-9:
                return t
        return np.nan

    def normal(self, x):
        return unit(x - self.c)

    def chart(self, x0, u, v):
        """Radial projection of the tangent plane at x0: derivative at (0, 0) is (e1, e2)."""
        e1, e2 = tangent_frame(self.normal(x0))
        return self.c + self.r * unit(x0 + u * e1 + v * e2 - self.c)


def trace(surface, o, d):
    t = surface.intersect(np.asarray(o, float), unit(d))
    return None if np.isnan(t) else np.asarray(o, float) + t * unit(d)


# --- tests of the helpers themselves -------------------------------------------------------------

def test_charts_are_orthonormal_at_the_origin():
    rng = np.random.default_rng(1)
    for _ in range(20):
        c, r = rng.normal(size=3), rng.uniform(0.5, 2)
        s = Sphere(c, r)
        x0 = c + r * unit(rng.normal(size=3))
        # the chart's FD Jacobian read at the sphere's own normal is 1 (area preserving at 0)
        assert abs(fd_jacobian(lambda u, v: (s.chart(x0, u, v), s.normal(x0))) - 1) < 1e-8
        w0 = unit(rng.normal(size=3))
        assert abs(fd_jacobian(lambda u, v: (direction_chart(w0, u, v), w0)) - 1) < 1e-8


def test_trace_hits_the_surfaces():
    s = Sphere([0, 0, 0], 1.0)
    p = trace(s, [0, 0, -3], [0, 0, 1])
    assert np.allclose(p, [0, 0, -1])
    assert trace(s, [0, 0, -3], [0, 1, 0]) is None
    pl = Plane([0, 0, 2], [0, 0, 1])
    assert np.allclose(trace(pl, [1, 1, 0], [0, 0, 1]), [1, 1, 2])
    assert trace(pl, [1, 1, 0], [0, 0, -1]) is None


def test_fd_jacobian_of_a_known_map():
    # scaling a plane chart by 3 in u and 2 in v has Jacobian 6: the FD helper must see it
    e = np.eye(3)
    assert abs(fd_jacobian(lambda u, v: (3 * u * e[0] + 2 * v * e[1], e[2])) - 6) < 1e-8
