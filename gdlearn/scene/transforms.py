"""``<transform name="to_world">``: 4x4 object-to-world matrices, composed as Mitsuba 3 does.

Mitsuba's XML parser (src/core/xml.cpp) starts from the identity and, for every child in document
order, left-multiplies the new transform: ``M = T_new @ M``. So ``<scale/><rotate/><translate/>``
is ``T @ R @ S``: scale first, then rotate, then translate. The elementary matrices follow
Mitsuba's ``Transform4f`` (include/mitsuba/core/transform.h):

* ``translate`` (x, y, z, missing = 0; or value with 1 or 3 components),
* ``scale`` (x, y, z, missing = 1; or value with 1 or 3 components),
* ``rotate`` axis (x, y, z) and ``angle`` in degrees: right-handed (Rodrigues) rotation; the axis
  must be a unit vector (Mitsuba uses it as given, so a longer one would shear: gdlearn refuses it),
* ``matrix`` value = 16 numbers row-major (or 9 for a 3x3 linear part),
* ``lookat`` origin, target, up: columns (left, up', dir, origin) with dir = normalize(target -
  origin), left = normalize(cross(up, dir)), up' = cross(dir, left); a missing ``up`` is the first
  vector of ``coordinate_system(dir)`` (Duff et al. 2017), as Mitsuba does.
"""
from __future__ import annotations

import numpy as np

from gdlearn.scene.model import SceneError
from gdlearn.scene.xmlvalues import Node, _check_attrs, _floats

TRANSFORM_TAGS = ("translate", "scale", "rotate", "matrix", "lookat")


def translate(v) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = v
    return m


def scale(v) -> np.ndarray:
    return np.diag([v[0], v[1], v[2], 1.0])


def rotate(axis, angle_deg) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    th = np.radians(angle_deg)
    c, s = np.cos(th), np.sin(th)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = c * np.eye(3) + s * k + (1 - c) * np.outer(a, a)
    return m


def coordinate_system(n):
    """Two unit vectors completing ``n`` to an orthonormal basis (Duff et al. 2017, as Mitsuba)."""
    sign = np.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    t = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    return s, t


def lookat(origin, target, up=None) -> np.ndarray:
    d = np.asarray(target, dtype=np.float64) - origin
    d = d / np.linalg.norm(d)
    if up is None or np.dot(up, up) == 0:
        up, _ = coordinate_system(d)
    left = np.cross(up, d)
    left = left / np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def _xyz(path, node, fill) -> np.ndarray:
    """x/y/z attributes (missing = ``fill``) or ``value`` with 1 or 3 components."""
    what = f"<{node.tag}>"
    if "value" in node.attrs:
        v = _floats(path, node, node.attrs["value"], what)
        if len(v) not in (1, 3):
            raise SceneError(path, node.line, f"{what} value needs 1 or 3 numbers, got {len(v)}",
                             'write value="x, y, z" or x="..." y="..." z="..."')
        return np.array(v * 3 if len(v) == 1 else v, dtype=np.float64)
    out = []
    for k in "xyz":
        out.append(_floats(path, node, node.attrs[k], what)[0] if k in node.attrs else fill)
    return np.array(out, dtype=np.float64)


def _vec3(path, node, key) -> np.ndarray:
    v = _floats(path, node, node.attrs[key], f"<{node.tag}> {key}")
    if len(v) != 3:
        raise SceneError(path, node.line, f"<{node.tag}> {key} needs 3 numbers, got {len(v)}",
                         f'write {key}="x, y, z"')
    return np.array(v, dtype=np.float64)


def element_matrix(path: str, node: Node) -> np.ndarray:
    """The 4x4 matrix of one transform element."""
    tag = node.tag
    if tag == "translate":
        _check_attrs(path, node, {"x", "y", "z", "value"})
        return translate(_xyz(path, node, 0.0))
    if tag == "scale":
        _check_attrs(path, node, {"x", "y", "z", "value"})
        return scale(_xyz(path, node, 1.0))
    if tag == "rotate":
        _check_attrs(path, node, {"x", "y", "z", "value", "angle"})
        if "angle" not in node.attrs:
            raise SceneError(path, node.line, "<rotate> has no angle",
                             'write <rotate x="1" angle="90"/> (axis x/y/z, angle in degrees)')
        axis = _xyz(path, node, 0.0)
        if not np.any(axis):
            raise SceneError(path, node.line, "<rotate> has a zero rotation axis",
                             'give the axis, e.g. <rotate y="1" angle="30"/>')
        if abs(np.linalg.norm(axis) - 1.0) > 1e-4:
            # Mitsuba's Transform4f::rotate assumes a unit axis and would silently shear the shape
            raise SceneError(path, node.line, f"<rotate> axis {axis.tolist()} is not a unit vector "
                             "(Mitsuba does not normalise it and would shear the shape)",
                             "normalise the axis, e.g. x=\"0.7071068\" y=\"0.7071068\"")
        angle = _floats(path, node, node.attrs["angle"], "<rotate> angle")
        return rotate(axis, angle[0])
    if tag == "matrix":
        _check_attrs(path, node, {"value"})
        v = _floats(path, node, node.attrs.get("value", ""), "<matrix>")
        if len(v) == 9:
            m = np.eye(4)
            m[:3, :3] = np.reshape(v, (3, 3))
            return m
        if len(v) != 16:
            raise SceneError(path, node.line, f"<matrix> needs 16 (or 9) numbers, got {len(v)}",
                             'write value="m00 m01 m02 m03 m10 ... m33" (row-major)')
        return np.reshape(np.array(v, dtype=np.float64), (4, 4))
    if tag == "lookat":
        _check_attrs(path, node, {"origin", "target", "up"})
        for key in ("origin", "target"):
            if key not in node.attrs:
                raise SceneError(path, node.line, f"<lookat> has no {key}",
                                 '<lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/>')
        o, t = _vec3(path, node, "origin"), _vec3(path, node, "target")
        up = _vec3(path, node, "up") if "up" in node.attrs else None
        d = t - o
        if not np.any(d) or (up is not None and np.any(up)
                             and np.linalg.norm(np.cross(up, d)) <= 1e-12 * np.linalg.norm(up) * np.linalg.norm(d)):
            raise SceneError(path, node.line, "invalid <lookat>: target equals origin or up is parallel "
                             "to the viewing direction", "move the target or choose an up vector not "
                             "parallel to target - origin")
        return lookat(o, t, up)
    raise SceneError(path, node.line, f"<{tag}> is not a transform",
                     f"inside <transform> use only {', '.join(TRANSFORM_TAGS)}")


def parse_transform(path: str, node: Node) -> np.ndarray:
    """The matrix of a ``<transform>`` element: children composed in document order."""
    _check_attrs(path, node, {"name"})
    m = np.eye(4)
    for child in node.children:
        m = element_matrix(path, child) @ m
    if not np.all(np.isfinite(m)):
        raise SceneError(path, node.line, "the transform is not finite",
                         "check the numbers of its elements")
    return m
