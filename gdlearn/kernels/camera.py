"""Mitsuba 3's ``perspective`` sensor: film position -> ray, and its inverse point -> film position.

Film coordinates are continuous raster coordinates: ``film_x`` in [0, W) grows to the right,
``film_y`` in [0, H) grows downwards; pixel (x, y) covers [x, x+1) x [y, y+1) (Mitsuba's box filter
samples exactly that square).

Mitsuba's camera looks along local +z; local +x points to the image's *left* and +y up (its
``lookat`` builds the columns (left, up, dir, origin), ``src/core/transform.cpp``), so the film
maps to the local direction ``((1 - 2 x/W) tx, (1 - 2 y/H) ty, 1)`` with ``tx = tan(fov_x / 2)`` and
``ty = tx / aspect`` (``src/sensors/perspective.cpp``). ``fov_axis`` picks which extent ``fov``
describes (x, y, diagonal, smaller, larger; ``include/mitsuba/render/sensor.h::parse_fov``).

The camera row ``cam`` (float64, ``CAM_WIDTH``) holds origin, the three world axes (unit, columns of
``to_world``), tx, ty, W, H, near and far clip. Rays start at the near-clip plane as in Mitsuba.
"""
import math

import numpy as np
from gdlearn.kernels.jit import block, leaf


CAM_O, CAM_X, CAM_Y, CAM_Z = 0, 3, 6, 9
CAM_TX, CAM_TY, CAM_W, CAM_H, CAM_NEAR, CAM_FAR = 12, 13, 14, 15, 16, 17
CAM_WIDTH = 18


def fov_x_tan(fov: float, fov_axis: str, width: int, height: int) -> float:
    """tan(fov_x / 2) for Mitsuba's fov / fov_axis conventions."""
    aspect = width / height
    axis = fov_axis
    if axis == "smaller":
        axis = "y" if aspect > 1 else "x"
    elif axis == "larger":
        axis = "x" if aspect > 1 else "y"
    t = math.tan(math.radians(fov) / 2)
    if axis == "x":
        return t
    if axis == "y":
        return t * aspect
    if axis == "diagonal":
        return t / math.sqrt(1.0 + 1.0 / aspect ** 2)
    raise ValueError(f"fov_axis must be x, y, diagonal, smaller or larger, not {fov_axis!r}")


def camera_row(to_world: np.ndarray, fov: float, fov_axis: str, width: int, height: int,
               near_clip: float = 0.01, far_clip: float = 10000.0) -> np.ndarray:
    """The camera row for a ``perspective`` sensor with the given ``to_world`` (4x4)."""
    m = np.asarray(to_world, dtype=np.float64)
    cam = np.zeros(CAM_WIDTH)
    cam[CAM_O:CAM_O + 3] = m[:3, 3]
    for k, col in ((CAM_X, 0), (CAM_Y, 1), (CAM_Z, 2)):
        v = m[:3, col]
        cam[k:k + 3] = v / np.linalg.norm(v)
    tx = fov_x_tan(fov, fov_axis, width, height)
    cam[CAM_TX], cam[CAM_TY] = tx, tx * height / width
    cam[CAM_W], cam[CAM_H] = width, height
    cam[CAM_NEAR], cam[CAM_FAR] = near_clip, far_clip
    return cam


# inlined (leaf): five calls per gpt sample and one per pt path; as a call it was 3-4 % of a pass
@leaf
def camera_ray(cam, film_x, film_y):
    """(origin, unit direction, tmax) of the primary ray through raster point (film_x, film_y)."""
    lx = (1.0 - 2.0 * film_x / cam[CAM_W]) * cam[CAM_TX]
    ly = (1.0 - 2.0 * film_y / cam[CAM_H]) * cam[CAM_TY]
    inv = 1.0 / math.sqrt(lx * lx + ly * ly + 1.0)      # = local d.z after normalising
    d = ((lx * cam[3] + ly * cam[6] + cam[9]) * inv,
         (lx * cam[4] + ly * cam[7] + cam[10]) * inv,
         (lx * cam[5] + ly * cam[8] + cam[11]) * inv)
    near_t = cam[CAM_NEAR] / inv
    o = (cam[0] + near_t * d[0], cam[1] + near_t * d[1], cam[2] + near_t * d[2])
    return o, d, cam[CAM_FAR] / inv - near_t


@block
def camera_raster(cam, p):
    """Inverse of :func:`camera_ray`: (visible, film_x, film_y) of world point ``p``.

    ``visible`` is False behind the camera, outside the film or outside the clip range.
    """
    rx = p[0] - cam[0]
    ry = p[1] - cam[1]
    rz = p[2] - cam[2]
    lx = rx * cam[3] + ry * cam[4] + rz * cam[5]
    ly = rx * cam[6] + ry * cam[7] + rz * cam[8]
    lz = rx * cam[9] + ry * cam[10] + rz * cam[11]
    if lz <= 0.0:
        return False, 0.0, 0.0
    fx = 0.5 * cam[CAM_W] * (1.0 - lx / (lz * cam[CAM_TX]))
    fy = 0.5 * cam[CAM_H] * (1.0 - ly / (lz * cam[CAM_TY]))
    dist = math.sqrt(rx * rx + ry * ry + rz * rz)
    zc = lz / dist      # cosine to the optical axis: clip planes are at near/far along +z
    ok = (0.0 <= fx < cam[CAM_W]) and (0.0 <= fy < cam[CAM_H]) and \
        (lz >= cam[CAM_NEAR]) and (lz <= cam[CAM_FAR]) and zc > 0.0
    return ok, fx, fy


