"""Reference solution of the exercise "offset-photon" (the book shows it in a dropdown).

gdlearn's compiled versions are ``gdlearn.shifts.photon.offset_target`` and
``projection_jacobian``, called by the photon half of the hybrid shift
(``gdlearn.integrators.photon.gpm_gather.shift_photon``); these are the same two formulas written
out in plain Python so that they can be read on their own.
"""
import math


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def offset_target(y, z, frame, z_o, frame_o):
    """Eq. 5 (Hua et al. 2017): the photon's offset from the gather point in local coordinates of
    the base frame, M^-1 (y - z) = (r . s, r . t, r . n), laid out again in the offset's frame."""
    n, s, t = frame
    n_o, s_o, t_o = frame_o
    r = (y[0] - z[0], y[1] - z[1], y[2] - z[2])
    a, b, c = _dot(r, s), _dot(r, t), _dot(r, n)
    return tuple(z_o[k] + a * s_o[k] + b * t_o[k] + c * n_o[k] for k in range(3))


def projection_jacobian(y_parent, y_star, n_star, y_hit, n_hit):
    """Eq. 6 (Hua et al. 2017): the projection keeps the solid angle seen from the parent, and
    dA = d^2 / |cos| dw at both ends, so |dy'/dy*| = (|cos*| / d*^2) / (|cos'| / d'^2)."""
    a = tuple(y_star[k] - y_parent[k] for k in range(3))
    b = tuple(y_hit[k] - y_parent[k] for k in range(3))
    da, db = _dot(a, a), _dot(b, b)
    if not (da > 0.0 and db > 0.0):
        return 0.0
    cos_star = abs(_dot(n_star, a)) / math.sqrt(da)
    cos_hit = abs(_dot(n_hit, b)) / math.sqrt(db)
    if not cos_hit > 0.0:
        return 0.0
    return (cos_star / da) / (cos_hit / db)
