"""Solution of the exercise "reconnection-jacobian" (exercises/reconnection-jacobian/README.md).

gdlearn implements this piece: :func:`gdlearn.shifts.reconnection.reconnection_jacobian_solid_angle`,

    |dw'/dw| = (|cos theta'_y| / |x'_b - y|^2) / (|cos theta_y| / |x_b - y|^2),

from dA_y = d^2 / |cos theta_y| dw on the base and on the offset segment (the area Jacobian is 1,
Hua et al. 2019 Sec. 3.3; GPM 2017 Eq. 4 solved for J_w). The solution only converts its arguments
to the float tuples the numba kernel takes.
"""
from gdlearn.shifts.reconnection import reconnection_jacobian_solid_angle


def _t(v):
    return (float(v[0]), float(v[1]), float(v[2]))


def reconnection_jacobian(x_b, x_b_offset, y, n_y) -> float:
    return float(reconnection_jacobian_solid_angle(_t(x_b), _t(x_b_offset), _t(y), _t(n_y)))


__all__ = ["reconnection_jacobian"]
