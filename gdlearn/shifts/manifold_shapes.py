"""The analytic shapes a specular chain lies on (:mod:`gdlearn.shifts.manifold`): a row of ``shapes``
per chain vertex, a plane quad (point, normal, two tangent axes, half extents; +-inf for an
unbounded plane) or a sphere (centre, radius; normal outward, local frame
``vec.coordinate_system(n)``), with each vertex's local frame and its 2-D chart."""
import math

import numpy as np

from gdlearn.kernels import vec
from gdlearn.kernels.jit import inlined, ir_inline

SHAPE_PLANE = 0
SHAPE_SPHERE = 1
SH_TYPE = 0
SH_P = 1        # 3: plane point / sphere centre
SH_N = 4        # 3: plane normal (outside, for eta = int/ext)
SH_U = 7        # 3: plane tangent axis 1 (unit)
SH_V = 10       # 3: plane tangent axis 2 (unit)
SH_EXT = 13     # 2: plane half extents along U, V (inf: unbounded)
SH_R = 15       # sphere radius
SH_WIDTH = 16


def plane_row(point, normal, u_axis, extent=(math.inf, math.inf)):
    """A plane (quad) row; u_axis is projected to the tangent plane; extent = half sizes along U, V."""
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    u = np.asarray(u_axis, float)
    u = u - np.dot(u, n) * n
    if not np.linalg.norm(u) > 1e-12:
        raise ValueError("plane_row: u_axis is parallel to the normal; fix: pass a tangent direction")
    u /= np.linalg.norm(u)
    row = np.zeros(SH_WIDTH)
    row[SH_TYPE] = SHAPE_PLANE
    row[SH_P:SH_P + 3], row[SH_N:SH_N + 3] = point, n
    row[SH_U:SH_U + 3], row[SH_V:SH_V + 3] = u, np.cross(n, u)
    row[SH_EXT:SH_EXT + 2] = extent
    return row


def sphere_row(center, radius):
    if not radius > 0:
        raise ValueError(f"sphere_row: radius must be > 0, got {radius!r}; fix: pass a positive radius")
    row = np.zeros(SH_WIDTH)
    row[SH_TYPE] = SHAPE_SPHERE
    row[SH_P:SH_P + 3] = center
    row[SH_R] = radius
    return row


@ir_inline
def _v3(a, i, c):
    return (a[i, c], a[i, c + 1], a[i, c + 2])


@inlined
def shape_frame(shapes, j, x):
    """(s, t, n) local frame of chain vertex j at x."""
    if int(shapes[j, SH_TYPE]) == SHAPE_PLANE:
        return _v3(shapes, j, SH_U), _v3(shapes, j, SH_V), _v3(shapes, j, SH_N)
    n = vec.normalize(vec.sub(x, _v3(shapes, j, SH_P)))
    s, t = vec.coordinate_system(n)
    return s, t, n


@inlined
def shape_chart(shapes, j, x, u, v):
    """Move x on its surface by (u, v) in the tangent frame (derivative at 0 is orthonormal)."""
    s, t, n = shape_frame(shapes, j, x)
    y = (x[0] + u * s[0] + v * t[0], x[1] + u * s[1] + v * t[1], x[2] + u * s[2] + v * t[2])
    if int(shapes[j, SH_TYPE]) == SHAPE_PLANE:
        return y
    c = _v3(shapes, j, SH_P)
    return vec.add(c, vec.scale(vec.normalize(vec.sub(y, c)), shapes[j, SH_R]))


@inlined
def shape_contains(shapes, j, x):
    if int(shapes[j, SH_TYPE]) != SHAPE_PLANE:
        return True
    d = vec.sub(x, _v3(shapes, j, SH_P))
    return (abs(vec.dot(d, _v3(shapes, j, SH_U))) <= shapes[j, SH_EXT]
            and abs(vec.dot(d, _v3(shapes, j, SH_V))) <= shapes[j, SH_EXT + 1])
