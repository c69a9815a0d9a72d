"""3-vectors as tuples of float64 -- numba keeps them in registers (no heap allocation in hot loops).

Every kernel passes points, directions and RGB colours as ``(x, y, z)`` tuples. Local shading frames
are orthonormal bases ``(s, t, n)`` with ``n`` the shading normal (z axis of the local frame), as in
Mitsuba's ``Frame3f``.
"""
import math
from gdlearn.kernels.jit import inlined



@inlined
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@inlined
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@inlined
def mul(a, b):
    """Component-wise product (colours)."""
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])


@inlined
def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)



@inlined
def neg(a):
    return (-a[0], -a[1], -a[2])


@inlined
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@inlined
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@inlined
def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@inlined
def normalize(a):
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n == 0.0:
        return (0.0, 0.0, 0.0)
    inv = 1.0 / n
    return (a[0] * inv, a[1] * inv, a[2] * inv)


@inlined
def fmin(a, b):
    """min(a, b) as a select, ``a`` unless b < a (Python's min): written out, since the builtin
    min/max are calls numba does not always inline, and a select lets a loop be vectorised."""
    return b if b < a else a


@inlined
def fmax(a, b):
    """max(a, b) as a select, ``a`` unless b > a (Python's max); see :func:`fmin`."""
    return b if b > a else a


@inlined
def max3(a):
    return max(a[0], max(a[1], a[2]))



@inlined
def coordinate_system(n):
    """An orthonormal basis (s, t) completing the unit vector n (Duff et al. 2017, branchless)."""
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    t = (b, sign + n[1] * n[1] * a, -n[1])
    return s, t


@inlined
def to_local(v, s, t, n):
    """World -> local shading frame (n is the z axis)."""
    return (dot(v, s), dot(v, t), dot(v, n))


@inlined
def to_world(v, s, t, n):
    """Local shading frame -> world."""
    return (s[0] * v[0] + t[0] * v[1] + n[0] * v[2],
            s[1] * v[0] + t[1] * v[1] + n[1] * v[2],
            s[2] * v[0] + t[2] * v[1] + n[2] * v[2])
