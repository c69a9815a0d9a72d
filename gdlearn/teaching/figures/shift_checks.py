"""The Jacobian check of the chapter "Shift mappings": every shift's analytic Jacobian against the
finite-difference Jacobian of the shift map itself, on random configurations (near-grazing included).

The shift map is differentiated as a black box: a base path's free coordinate (a direction on the
unit sphere, or a vertex on its surface) is moved in a 2-D chart whose derivative at the expansion
point is orthonormal, the offset is recomputed by gdlearn's shift, and the offset coordinate is read
in an orthonormal chart at the offset. The |determinant| of the 2x2 matrix of central differences is then
the Jacobian in the solid-angle or area measure (the harness and its error analysis:
:mod:`gdlearn.testing.fdjac`). The test suite asserts
the same comparisons (tests/test_shifts_*.py); here they are tabulated for the reader.
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.shifts import manifold as M
from gdlearn.shifts.halfvector import halfvector_copy
from gdlearn.shifts.path import jacobian_solid_angle_to_area
from gdlearn.shifts.reconnection import reconnection_jacobian_solid_angle
from gdlearn.testing.fdjac import H, fd_determinant, read_in_chart, tangent_frame, unit  # noqa: F401

def _hit_plane(o, d, p, n):
    den = float(np.dot(d, n))
    t = float(np.dot(np.subtract(p, o), n)) / den if den != 0 else -1.0
    return o + t * d if t > 1e-9 else None


def reconnection_case(rng, grazing):
    """(analytic, fd) for reconnection x_b -> y  ==>  x'_b -> y on a random tilted plane."""
    n = unit(rng.normal(size=3) * [0.3, 0.3, 1.0] + [0, 0, 1])
    y = rng.normal(size=3) * 0.3
    e1, _ = tangent_frame(n)
    x_b = y + 3 * unit(e1 + rng.uniform(0.01, 0.05) * n) if grazing else y + unit(rng.normal(size=3) * 0.4 + n) * 3
    x_o = x_b + rng.normal(size=3) * 0.1
    w0 = unit(y - x_b)

    def m(u, v):
        e1w, e2w = tangent_frame(w0)
        hit = _hit_plane(x_b, unit(w0 + u * e1w + v * e2w), y, n)
        return None if hit is None else read_in_chart(unit(hit - x_o), unit(y - x_o))
    j = reconnection_jacobian_solid_angle(tuple(x_b), tuple(x_o), tuple(y), tuple(n))
    return j, fd_determinant(m), abs(float(np.dot(n, w0)))


def _scatter(wi, h, eta, refract):
    """Reflection / refraction of wi about h (Snell in vector form, written independently of gdlearn)."""
    c = float(np.dot(wi, h))
    if not refract:
        return 2 * c * h - wi
    eta_ti = 1.0 / eta if c > 0 else eta
    s2 = eta_ti ** 2 * (1 - c * c)
    if s2 >= 1:
        return None
    return unit(-eta_ti * wi + (eta_ti * c - math.copysign(math.sqrt(1 - s2), c)) * h)


def halfvector_case(rng, grazing, refract, eta=1.5):
    """(analytic, fd) for the half-vector copy's solid-angle Jacobian |dw'_o/dw_o| (local frame)."""
    while True:
        z = rng.uniform(0.01, 0.04) if grazing else rng.uniform(0.2, 1.0)
        phi = rng.uniform(0, 2 * math.pi)
        wi = np.array([math.sqrt(1 - z * z) * math.cos(phi), math.sqrt(1 - z * z) * math.sin(phi), z])
        h = np.array([0, 0, 1.0]) if grazing else unit([rng.normal() * 0.35, rng.normal() * 0.35, 1.0])
        wo = _scatter(wi, h, eta, refract)
        if wo is None or np.dot(wi, h) <= 0 or wo[2] * (-1 if refract else 1) <= 0 or np.dot(wo, h) * wo[2] <= 0:
            continue
        wi_o = unit(wi + rng.normal(size=3) * (0.005 if grazing else 0.1))
        wo_o, j, ok = halfvector_copy(tuple(wi), tuple(wo), tuple(wi_o), eta, True)
        if ok:
            break

    def m(u, v):
        e1, e2 = tangent_frame(wo)
        w, _, good = halfvector_copy(tuple(wi), tuple(unit(wo + u * e1 + v * e2)), tuple(wi_o), eta, True)
        return read_in_chart(np.array(w), np.array(wo_o)) if good else None
    return j, fd_determinant(m), abs(wi[2])


def halfvector_area_case(rng, refract, eta=1.5):
    """(analytic, fd) for the half-vector copy in the area measure (GPM Eq. 4): the base's next
    vertex z_{i+1} moves on a tilted plane, the offset's is traced along the copied direction."""
    side = -1.0 if refract else 1.0
    n2 = unit([rng.normal() * 0.4, rng.normal() * 0.4, 1.0])
    p2 = np.array([0, 0, side * 2.0])
    z_i = np.array([rng.normal() * 0.2, rng.normal() * 0.2, 0.0])
    z_o = z_i + [rng.normal() * 0.05, rng.normal() * 0.05, 0.0]
    wi_b = unit([rng.normal() * 0.5, rng.normal() * 0.5, 1.0])
    wi_o = unit(wi_b + rng.normal(size=3) * 0.05)
    wo0 = _scatter(wi_b, unit([rng.normal() * 0.2, rng.normal() * 0.2, 1.0]), eta, refract)
    y0 = None if wo0 is None else _hit_plane(z_i, wo0, p2, n2)
    if y0 is None:
        return None

    def offset_vertex(y):
        w, j, ok = halfvector_copy(tuple(wi_b), tuple(unit(y - z_i)), tuple(wi_o), eta, True)
        return (None, 0.0) if not ok else (_hit_plane(z_o, np.array(w), p2, n2), j)
    yo0, j_w = offset_vertex(y0)
    if yo0 is None:
        return None
    e1, e2 = tangent_frame(n2)

    def m(u, v):
        yo, _ = offset_vertex(y0 + u * e1 + v * e2)
        return None if yo is None else np.array([np.dot(yo - yo0, e1), np.dot(yo - yo0, e2)])
    j = jacobian_solid_angle_to_area(j_w, tuple(z_i), tuple(y0), tuple(n2), tuple(z_o), tuple(yo0), tuple(n2))
    return j, fd_determinant(m), abs(float(np.dot(n2, unit(y0 - z_i))))


def _hit_sphere(o, d, c, r):
    oc = o - c
    b = float(np.dot(oc, d))
    disc = b * b - (float(np.dot(oc, oc)) - r * r)
    if disc < 0:
        return None
    for t in (-b - math.sqrt(disc), -b + math.sqrt(disc)):
        if t > 1e-9:
            return o + t * d
    return None


#: The glass ball of the manifold check (unit radius at the origin, eta 1.5) and the floor below it,
#: before the ball lens's focus (back focal distance 0.5 R): past it the walk nears a caustic.
BALL_ETA, FLOOR_Z = 1.5, -1.3


def _ball_chain(x_b, x1):
    """Trace x_b -> x1 (on the ball) through the ball to the floor: (chain (2 x 3), x_c) or None."""
    pts, d = [x1], unit(x1 - x_b)
    for _ in range(2):
        d = _scatter(-d, unit(pts[-1]), BALL_ETA, True)
        if d is None:
            return None
        nxt = _hit_sphere(pts[-1], d, np.zeros(3), 1.0) if len(pts) == 1 else _hit_plane(pts[-1], d, [0, 0, FLOOR_Z], [0, 0, 1.0])
        if nxt is None:
            return None
        pts.append(nxt)
    return np.ascontiguousarray(pts[:2]), pts[2]


def _ball_shift(x_b, chain, x_c, x_bo):
    rows = np.array([M.sphere_row([0, 0, 0], 1.0)] * 2)
    out = np.zeros((2, 3))
    j, ok, _ = M.manifold_shift(tuple(x_b), tuple(x_bo), chain, tuple(x_c), (0.0, 0.0, 1.0), rows,
                                np.full(2, BALL_ETA), np.array([True, True]), 2, out, M.MAX_ITER, False)
    return j, ok, out


def manifold_case(rng):
    """(analytic, fd) for the manifold shift of a two-refraction chain through a glass ball (GPM Eq.
    7-8): the base's x_1 moves on the ball, the base chain is re-traced to a new x_c, the walk re-run."""
    x_b = np.array([rng.normal() * 0.3, rng.normal() * 0.3, 3.0])
    x1 = unit([rng.normal() * 0.25, rng.normal() * 0.25, 1.0])
    base = _ball_chain(x_b, x1)
    if base is None:
        return None
    x_bo = x_b + rng.normal(size=3) * 0.02
    j, ok, out = _ball_shift(x_b, base[0], base[1], x_bo)
    if not ok:
        return None
    x1o = out[0].copy()
    e1, e2 = tangent_frame(x1)

    def m(u, v):
        b = _ball_chain(x_b, unit(x1 + u * e1 + v * e2))
        if b is None:
            return None
        _, good, o = _ball_shift(x_b, b[0], b[1], x_bo)
        return read_in_chart(o[0] - x1o, x1o) if good else None
    # h = 1e-4: the walk converges to |c| < 1e-12, so its positions carry ~1e-14 noise (FD round-off
    # ~1e-10); the Jacobian inside manifold_shift is itself a central difference (~1e-9)
    return j, fd_determinant(m, h=1e-4), abs(float(np.dot(x1, unit(x1 - x_b))))


CASES = (("reconnection", "ordinary", lambda r: reconnection_case(r, False)),
         ("reconnection", "near-grazing", lambda r: reconnection_case(r, True)),
         ("half-vector reflection", "ordinary", lambda r: halfvector_case(r, False, False)),
         ("half-vector reflection", "near-grazing", lambda r: halfvector_case(r, True, False)),
         ("half-vector refraction", "ordinary", lambda r: halfvector_case(r, False, True)),
         ("half-vector refraction", "near-grazing", lambda r: halfvector_case(r, True, True)),
         ("half-vector reflection, area", "ordinary", lambda r: halfvector_area_case(r, False)),
         ("half-vector refraction, area", "ordinary", lambda r: halfvector_area_case(r, True)),
         ("manifold, glass ball (k=2)", "ordinary", manifold_case))


def jacobian_table(n: int, seed: int):
    """Run every case of :data:`CASES` ``n`` times; records (shift, case, cos, analytic, fd, rel_err)
    for the configurations where both the shift and its finite difference succeed."""
    rng = np.random.default_rng(seed)
    rows = []
    for shift, case, make in CASES:
        for _ in range(n):
            res = make(rng)
            if res is None or res[1] is None:
                continue
            j, fd, cos = res
            rows.append(dict(shift=shift, case=case, cos=cos, analytic=float(j), fd=float(fd),
                             rel_err=abs(float(j) / float(fd) - 1.0)))
    return rows


def summary(rows) -> str:
    """One line per (shift, case): configurations checked, range of |J|, smallest cosine, how far J is
    from 1 (what a shift that ignored its Jacobian would get wrong), worst relative error."""
    lines = [f"{'shift':30s} {'case':13s} {'n':>3s} {'min J':>8s} {'max J':>8s} {'min cos':>8s} {'max |J-1|':>9s} {'max rel err':>11s}"]
    keys = dict.fromkeys((r["shift"], r["case"]) for r in rows)
    for shift, case in keys:
        sel = [r for r in rows if (r["shift"], r["case"]) == (shift, case)]
        js = [r["analytic"] for r in sel]
        lines.append(f"{shift:30s} {case:13s} {len(sel):3d} {min(js):8.4f} {max(js):8.4f} "
                     f"{min(r['cos'] for r in sel):8.4f} {max(abs(j - 1) for j in js):9.3f} "
                     f"{max(r['rel_err'] for r in sel):11.2e}")
    return "\n".join(lines)


__all__ = ["fd_determinant", "reconnection_case", "halfvector_case", "halfvector_area_case", "manifold_case",
           "jacobian_table", "summary", "CASES"]
