"""Synthetic geometry for the shift-mapping tests (planes and spheres in numpy), the finite-difference
Jacobian of a map between 2-D charts, and tests of these helpers themselves.

The shift tests differentiate the shift map *itself*: a base path's free coordinate (a vertex moved
on its surface in a 2-D chart, or a direction moved on the unit sphere) is perturbed, the offset path
is recomputed by ray tracing these surfaces, and the offset's coordinate is read in a chart at the
offset point. Every chart used here has an orthonormal derivative at the point of expansion, so the
determinant of the 2x2 finite-difference matrix is the Jacobian in the area / solid-angle measure.

Fourth-order central differences, f' ~ [-f(2h) + 8 f(h) - 8 f(-h) + f(-2h)] / 12h: error
~ h^4 |f^(5)| / 30 + eps |f| / h. With h = 1e-6 on O(1) geometry that is ~1e-25 |f^(5)| + 1e-10.
Near-grazing hits on a sphere are the hard case: the hit point depends on the direction like a
square root near tangency, so |f^(5)| grows like cos^-9 (measured: h = 1e-4 misses by 1e-5 at
cos ~ 0.03, h = 1e-6 and 1e-7 agree to 1e-9). So the shift tests ask for 1e-6 relative agreement
and still fail on any wrong cosine or distance factor (an O(1) error).
"""
import numpy as np

H = 1e-6


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def tangent_frame(n):
    """Orthonormal (e1, e2) completing the unit vector n (any continuous choice works for charts)."""
    n = unit(n)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = unit(np.cross(n, a))
    return e1, np.cross(n, e1)


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


def direction_chart(w0, u, v):
    """Chart of the unit sphere at w0 (gnomonic projection; derivative at 0 is orthonormal)."""
    e1, e2 = tangent_frame(w0)
    return unit(w0 + u * e1 + v * e2)


def fd_jacobian(f, h=H):
    """|det| of the 2x2 derivative of f: (u, v) -> 3-vector, read in an orthonormal basis of the
    plane orthogonal to ``normal_out`` at f(0, 0). f returns (point, normal_out) or None."""
    f0 = f(0.0, 0.0)
    if f0 is None:
        return None
    _, n_out = f0
    e1, e2 = tangent_frame(n_out)
    cols = []
    for du, dv in ((h, 0.0), (0.0, h)):
        pts = [f(k * du, k * dv) for k in (2, 1, -1, -2)]
        if any(p is None for p in pts):
            return None
        d = (-pts[0][0] + 8 * pts[1][0] - 8 * pts[2][0] + pts[3][0]) / (12 * h)
        cols.append([np.dot(d, e1), np.dot(d, e2)])
    return abs(np.linalg.det(np.array(cols).T))


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
