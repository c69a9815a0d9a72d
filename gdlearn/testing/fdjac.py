"""The finite-difference Jacobian of a shift map, the one harness every Jacobian check uses.

A shift's Jacobian is checked by differentiating the shift map *itself*: a base path's free
coordinate (a direction on the unit sphere, or a vertex on its surface) is moved in a 2-D chart
whose derivative at the expansion point is orthonormal, the offset is recomputed by the shift, and
the offset coordinate is read in an orthonormal chart at the offset. The |determinant| of the 2x2
matrix of derivatives is then the Jacobian in the solid-angle or area measure.

Derivatives are fourth-order central differences, f' ~ [-f(2h) + 8 f(h) - 8 f(-h) + f(-2h)] / 12h,
with error ~ h^4 |f^(5)| / 30 + eps |f| / h: with h = 1e-6 on O(1) geometry ~1e-10. Near-grazing
hits on a sphere are the hard case (the hit point moves like a square root near tangency, so
|f^(5)| grows like cos^-9): h = 1e-4 misses by 1e-5 at cos ~ 0.03, while h = 1e-6 and 1e-7 agree
to 1e-9. Checks therefore ask for 1e-6 relative agreement, which still fails any wrong cosine or
distance factor (an O(1) error).
"""
from __future__ import annotations

import numpy as np

#: the step of the central differences (see the module docstring)
H = 1e-6


def unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def tangent_frame(n) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal (e1, e2) completing the unit vector n (any continuous choice works for charts)."""
    n = unit(n)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = unit(np.cross(n, a))
    return e1, np.cross(n, e1)


def direction_chart(w0, u: float, v: float) -> np.ndarray:
    """Chart of the unit sphere at w0 (gnomonic projection; its derivative at 0 is orthonormal)."""
    e1, e2 = tangent_frame(w0)
    return unit(np.asarray(w0, float) + u * e1 + v * e2)


def read_in_chart(w, w0) -> np.ndarray:
    """Coordinates of w in the orthonormal tangent chart at w0 (a direction or a surface normal)."""
    e1, e2 = tangent_frame(w0)
    return np.array([np.dot(w, e1), np.dot(w, e2)])


def fd_determinant(m, h: float = H) -> float | None:
    """|det| of the 2x2 derivative at 0 of ``m(u, v) -> 2-vector``; None if m returns None anywhere
    in the stencil (the shift failed there)."""
    cols = []
    for du, dv in ((h, 0.0), (0.0, h)):
        vals = [m(k * du, k * dv) for k in (2, 1, -1, -2)]
        if any(v is None for v in vals):
            return None
        cols.append((-vals[0] + 8 * vals[1] - 8 * vals[2] + vals[3]) / (12 * h))
    return abs(float(np.linalg.det(np.array(cols).T)))


def fd_jacobian_at_point(f, h: float = H) -> float | None:
    """|det| of the derivative of ``f(u, v) -> (point, normal_out)`` with the point read in the
    orthonormal chart of the plane orthogonal to ``normal_out`` at f(0, 0) (an area-measure
    Jacobian); None if f fails anywhere in the stencil."""
    f0 = f(0.0, 0.0)
    if f0 is None:
        return None
    p0, n_out = f0
    e1, e2 = tangent_frame(n_out)

    def m(u, v):
        r = f(u, v)
        return None if r is None else np.array([np.dot(r[0] - p0, e1), np.dot(r[0] - p0, e2)])
    return fd_determinant(m, h)


__all__ = ["H", "unit", "tangent_frame", "direction_chart", "read_in_chart", "fd_determinant",
           "fd_jacobian_at_point"]
