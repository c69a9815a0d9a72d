"""Scene -> SceneArrays: the flat, numba-ready form of a validated :class:`~gdlearn.scene.model.Scene`.

Every kernel takes the compiled scene ``sa`` (a NamedTuple of contiguous arrays, which numba passes
as a struct of array views: no per-call cost inside compiled code) and reads:

================  ===========================  ==================================================
field             dtype / shape                meaning
================  ===========================  ==================================================
prims             f64 (N, PRIM_WIDTH)          primitive rows (kernels/geometry.py), BVH order
prim_info         i32 (N, INFO_WIDTH)          type, material, emitter, media, shape index
prim_area         f64 (N,)                     surface area of each primitive
nodes, node_info  f64 (K,), i32 (M, 5)         BVH: boxes, leaf lane blocks (kernels/accel/bvh.py)
materials         f64 (B, MAT_WIDTH)           BSDF rows (kernels/layout.py, bsdf.material_row);
                                               its write flag and order name its tier (bsdf.tiers)
media             f64 (K, MED_WIDTH)           homogeneous media (sigma_t, albedo, g)
emitters          f64 (E, EM_WIDTH)            emitter rows (kernels/lights.py)
em_prims, em_cdf  i32 (P,), f64 (P,)           area emitters' primitives, normalised area CDFs
camera            f64 (CAM_WIDTH,)             perspective camera (kernels/camera.py)
bsphere           f64 (4,)                     scene bounding sphere: centre, radius
env               int                          row of the constant emitter, -1 if none
camera_medium     int                          medium row the camera sits in, -1 = vacuum
================  ===========================  ==================================================

Rectangles and cubes become triangles exactly as Mitsuba 3 tessellates them (a rectangle is the
quad [-1,1]^2 x {0}; a cube is the mesh of [-1,1]^3 with outward faces), spheres and disks stay
analytic. Shapes keep their ``Source`` so geometry errors name the scene file and line.
"""
from __future__ import annotations

import math
import numpy as np

from gdlearn.kernels.accel import bvh as _bvh
from gdlearn.kernels import geometry as g
from gdlearn.kernels import layout as L
from gdlearn.kernels import lights as li
from gdlearn.kernels.bsdf.tiers import tiered_table
from gdlearn.kernels.camera import camera_row
from gdlearn.kernels.arrays import SceneArrays
from gdlearn.scene.model import Scene, SceneError


# ----------------------------------------------------------------------------------- tessellation
_RECT = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)


def _xform(m, pts):
    return pts @ m[:3, :3].T + m[:3, 3]


def _normal_xform(m, n):
    """A normal transformed as Mitsuba does (inverse transpose), normalised."""
    v = np.linalg.inv(m[:3, :3]).T @ n
    return v / np.linalg.norm(v)


def _quad_tris(p, n):
    """Two triangles (p0 p1 p2), (p0 p2 p3) of a planar quad, wound so cross(e1, e2) agrees with n."""
    tris = [(p[0], p[1], p[2]), (p[0], p[2], p[3])]
    out = []
    for a, b, c in tris:
        if np.dot(np.cross(b - a, c - a), n) < 0:
            b, c = c, b
        out.append((a, b, c, n))
    return out


def _tri_row(a, b, c, n, vn=None):
    row = np.zeros(g.PRIM_WIDTH)
    row[g.G_P0:g.G_P0 + 3] = a
    row[g.G_E1:g.G_E1 + 3] = b - a
    row[g.G_E2:g.G_E2 + 3] = c - a
    row[g.G_NG:g.G_NG + 3] = n
    if vn is not None:
        row[g.G_N0:g.G_N0 + 9] = np.concatenate(vn)
        row[g.G_HASN] = 1.0
    return row


def _shape_prims(shape):
    """(rows, types, areas, lo, hi) of one shape's primitives."""
    m = np.asarray(shape.to_world, dtype=np.float64)
    sgn = -1.0 if shape.flip_normals else 1.0
    rows, types = [], []
    if shape.type == "rectangle":
        n = sgn * _normal_xform(m, np.array([0.0, 0.0, 1.0]))
        for a, b, c, nn in _quad_tris(_xform(m, _RECT), n):
            rows.append(_tri_row(a, b, c, nn))
            types.append(g.P_TRIANGLE)
    elif shape.type == "cube":
        for axis in range(3):
            for side in (-1.0, 1.0):
                # face of [-1,1]^3 at x_axis = side, outward normal side * e_axis
                u, v = (axis + 1) % 3, (axis + 2) % 3
                q = np.zeros((4, 3))
                q[:, axis] = side
                q[:, u] = _RECT[:, 0]
                q[:, v] = _RECT[:, 1]
                nl = np.zeros(3)
                nl[axis] = side
                n = sgn * _normal_xform(m, nl)
                for a, b, c, nn in _quad_tris(_xform(m, q), n):
                    rows.append(_tri_row(a, b, c, nn))
                    types.append(g.P_TRIANGLE)
    elif shape.type == "sphere":
        c = m[:3, 3]
        axes = np.linalg.norm(m[:3, :3], axis=0)
        if not np.allclose(axes, axes[0], rtol=1e-6):
            raise SceneError(shape.src.file, shape.src.line, "a sphere's to_world scales its axes unequally "
                             f"({axes.round(6).tolist()}): ellipsoids are not supported",
                             "use a uniform scale (or the radius parameter)")
        row = np.zeros(g.PRIM_WIDTH)
        row[g.G_C:g.G_C + 3] = c
        row[g.G_R] = axes[0]
        row[g.G_SIGN] = sgn
        rows.append(row)
        types.append(g.P_SPHERE)
    elif shape.type == "disk":
        row = np.zeros(g.PRIM_WIDTH)
        a, b = m[:3, 0], m[:3, 1]
        n = sgn * _normal_xform(m, np.array([0.0, 0.0, 1.0]))
        row[g.G_C:g.G_C + 3] = m[:3, 3]
        row[g.G_A:g.G_A + 3] = a
        row[g.G_B:g.G_B + 3] = b
        row[g.G_NG:g.G_NG + 3] = n
        # dual axes: dot(p - c, da) = u, dot(p - c, db) = v for p = c + u a + v b
        gram = np.array([[a @ a, a @ b], [a @ b, b @ b]])
        inv = np.linalg.inv(gram)
        row[g.G_DA:g.G_DA + 3] = inv[0, 0] * a + inv[0, 1] * b
        row[g.G_DB:g.G_DB + 3] = inv[1, 0] * a + inv[1, 1] * b
        rows.append(row)
        types.append(g.P_DISK)
    elif shape.type in ("obj", "ply"):
        rows, types = _mesh_rows(shape, sgn)
    else:
        raise SceneError(shape.src.file, shape.src.line, f"shape type {shape.type!r} cannot be compiled",
                         "use rectangle, cube, sphere, disk, obj or ply")
    rows = np.array(rows, dtype=np.float64).reshape(-1, g.PRIM_WIDTH)
    types = np.array(types, dtype=np.int32)
    areas, lo, hi = _bounds(rows, types)
    if np.any(areas <= 0.0) or not np.all(np.isfinite(rows)):
        raise SceneError(shape.src.file, shape.src.line, f"{shape.type} {shape.id or ''} has zero area or "
                         "non-finite coordinates after its to_world transform", "check the shape's transform")
    return rows, types, areas, lo, hi


def _mesh_rows(shape, sgn):
    v = np.asarray(shape.vertices, dtype=np.float64)
    f = np.asarray(shape.faces, dtype=np.int64)
    if v.ndim != 2 or len(f) == 0:
        raise SceneError(shape.src.file, shape.src.line, f"mesh {shape.filename!r} is empty", "check the file")
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cr = np.cross(b - a, c - a)
    ln = np.linalg.norm(cr, axis=1)
    keep = ln > 0.0      # degenerate triangles cannot be hit or sampled: drop them
    if not keep.any():
        raise SceneError(shape.src.file, shape.src.line, f"mesh {shape.filename!r} has only degenerate "
                         "triangles", "check the file")
    ng = sgn * cr[keep] / ln[keep, None]
    vn = None
    if shape.normals is not None and not shape.face_normals:
        nv = np.asarray(shape.normals, dtype=np.float64)
        nv = sgn * nv / np.maximum(np.linalg.norm(nv, axis=1, keepdims=True), 1e-300)
        vn = (nv[f[keep, 0]], nv[f[keep, 1]], nv[f[keep, 2]])
    rows = []
    a, b, c = a[keep], b[keep], c[keep]
    for i in range(len(a)):
        rows.append(_tri_row(a[i], b[i], c[i], ng[i], None if vn is None else (vn[0][i], vn[1][i], vn[2][i])))
    return rows, [g.P_TRIANGLE] * len(rows)


def _bounds(rows, types):
    n = len(rows)
    areas, lo, hi = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3))
    for i in range(n):
        r = rows[i]
        if types[i] == g.P_TRIANGLE:
            p0, e1, e2 = r[0:3], r[3:6], r[6:9]
            pts = np.stack([p0, p0 + e1, p0 + e2])
            areas[i] = 0.5 * np.linalg.norm(np.cross(e1, e2))
            lo[i], hi[i] = pts.min(0), pts.max(0)
        elif types[i] == g.P_SPHERE:
            c, rad = r[0:3], r[g.G_R]
            areas[i] = 4.0 * math.pi * rad * rad
            lo[i], hi[i] = c - rad, c + rad
        else:
            c, a, b = r[0:3], r[3:6], r[6:9]
            areas[i] = math.pi * np.linalg.norm(np.cross(a, b))
            ext = np.sqrt(a * a + b * b)
            lo[i], hi[i] = c - ext, c + ext
    return areas, lo, hi


# ---------------------------------------------------------------------------------------- tables
def _material_rows(bsdfs) -> np.ndarray:
    """Developer C's rows; widened for a roughplastic's transmittance table when one is present."""
    from gdlearn.kernels.bsdf.dispatch import material_row
    from gdlearn.kernels.bsdf.plastic import ROUGHPLASTIC_WIDTH
    width = L.MAT_WIDTH
    if any(b.type == "roughplastic" for b in bsdfs):
        width = max(width, ROUGHPLASTIC_WIDTH)
    rows = []
    for b in bsdfs:
        try:
            rows.append(np.asarray(material_row(b, width), dtype=np.float64))
        except ValueError as err:
            raise SceneError(b.src.file, b.src.line, str(err), "fix the bsdf's parameters") from None
    return np.array(rows, dtype=np.float64).reshape(-1, width)


def _medium_row(med) -> np.ndarray:
    row = np.zeros(L.MED_WIDTH)
    row[L.MED_SIGMA_T:L.MED_SIGMA_T + 3] = med.sigma_t
    row[L.MED_ALBEDO:L.MED_ALBEDO + 3] = med.albedo
    row[L.MED_G] = med.g if med.phase == "hg" else 0.0
    return row


class _Index:
    """Rows of unique objects (by identity), in first-seen order."""

    def __init__(self):
        self.ids, self.objs = {}, []

    def __call__(self, obj):
        if obj is None:
            return -1
        k = id(obj)
        if k not in self.ids:
            self.ids[k] = len(self.objs)
            self.objs.append(obj)
        return self.ids[k]


def _new_emitter_row(bs) -> np.ndarray:
    """An empty emitter row holding the scene's bounding sphere ``bs`` (centre, radius): the shadow
    rays to emitters at infinity need both (``lights.infinite_distance``)."""
    row = np.zeros(li.EM_WIDTH)
    row[li.EM_BS_R] = bs[3]
    row[li.EM_BS_C:li.EM_BS_C + 3] = bs[:3]
    return row


def _emitter_row(em, bs) -> np.ndarray:
    row = _new_emitter_row(bs)
    m = np.asarray(em.to_world, dtype=np.float64)
    if em.type == "point":
        row[li.EM_TYPE] = li.E_POINT
        row[li.EM_RGB:li.EM_RGB + 3] = em.intensity
        row[li.EM_P:li.EM_P + 3] = em.position if em.position is not None else m[:3, 3]
    elif em.type == "spot":
        row[li.EM_TYPE] = li.E_SPOT
        row[li.EM_RGB:li.EM_RGB + 3] = em.intensity
        row[li.EM_P:li.EM_P + 3] = m[:3, 3]
        cutoff = math.radians(em.cutoff_angle)
        beam = math.radians(em.beam_width if em.beam_width is not None else 0.75 * em.cutoff_angle)
        row[li.EM_COS_CUTOFF], row[li.EM_COS_BEAM] = math.cos(cutoff), math.cos(beam)
        row[li.EM_CUTOFF] = cutoff
        row[li.EM_INV_TRANS] = 1.0 / (cutoff - beam) if cutoff > beam else 0.0
        row[li.EM_INV:li.EM_INV + 9] = np.linalg.inv(m[:3, :3]).reshape(-1)
    elif em.type == "directional":
        row[li.EM_TYPE] = li.E_DIRECTIONAL
        row[li.EM_RGB:li.EM_RGB + 3] = em.irradiance
        d = np.asarray(em.direction if em.direction is not None else m[:3, 2], dtype=np.float64)
        row[li.EM_D:li.EM_D + 3] = d / np.linalg.norm(d)
    elif em.type == "constant":
        row[li.EM_TYPE] = li.E_CONSTANT
        row[li.EM_RGB:li.EM_RGB + 3] = em.radiance
    else:
        raise SceneError(em.src.file, em.src.line, f"emitter type {em.type!r} cannot be compiled",
                         "use area, point, spot, directional or constant")
    return row


# ---------------------------------------------------------------------------------------- compile
def compile_scene(scene: Scene, plan=None) -> SceneArrays:
    """Flatten ``scene`` into :class:`SceneArrays` (``plan`` is accepted for estimators that drop
    parts of the scene; the arrays themselves do not depend on it yet)."""
    if not scene.shapes:
        raise SceneError(scene.path, None, "the scene has no shapes", "add at least one <shape>")
    mats, meds = _Index(), _Index()
    rows, info, areas, lo, hi = [], [], [], [], []
    shape_of_emitter = []
    for si, sh in enumerate(scene.shapes):
        r, t, a, l, h = _shape_prims(sh)
        has_med = sh.interior is not None or sh.exterior is not None
        em = len(shape_of_emitter) if sh.emitter is not None else -1
        if em >= 0:
            shape_of_emitter.append(si)
        inf = np.zeros((len(r), g.INFO_WIDTH), dtype=np.int32)
        inf[:, g.INFO_TYPE] = t
        inf[:, g.INFO_MAT] = mats(sh.bsdf)
        inf[:, g.INFO_EMITTER] = em
        inf[:, g.INFO_MED_INT] = meds(sh.interior)
        inf[:, g.INFO_MED_EXT] = meds(sh.exterior)
        inf[:, g.INFO_MED_TRANS] = int(has_med)
        inf[:, g.INFO_SHAPE] = si
        rows.append(r), info.append(inf), areas.append(a), lo.append(l), hi.append(h)
    rows, info, areas = np.concatenate(rows), np.concatenate(info), np.concatenate(areas)
    lo, hi = np.concatenate(lo), np.concatenate(hi)
    order, nodes, node_info = _bvh.build_scene(rows, info[:, g.INFO_TYPE], info[:, g.INFO_SHAPE], lo, hi)
    rows, info, areas = rows[order], info[order], areas[order]
    bmin, bmax = lo.min(0), hi.max(0)
    bs = np.concatenate([(bmin + bmax) / 2, [np.linalg.norm(bmax - bmin) / 2]])

    em_rows, em_prims, em_cdf = [], [], []
    for em, si in enumerate(shape_of_emitter):
        idx = np.nonzero(info[:, g.INFO_EMITTER] == em)[0]
        a = areas[idx]
        row = _new_emitter_row(bs)
        row[li.EM_TYPE] = li.E_AREA
        row[li.EM_RGB:li.EM_RGB + 3] = scene.shapes[si].emitter.radiance
        row[li.EM_FIRST], row[li.EM_COUNT], row[li.EM_AREA] = len(em_prims), len(idx), a.sum()
        em_rows.append(row)
        em_prims.extend(idx.tolist())
        cdf = np.cumsum(a) / a.sum()
        cdf[-1] = 1.0
        em_cdf.extend(cdf.tolist())
    env = -1
    for em in scene.emitters:
        if em.type == "constant":
            if env >= 0:
                raise SceneError(em.src.file, em.src.line, "more than one constant emitter",
                                 "keep one <emitter type=\"constant\"> (Mitsuba allows one environment)")
            env = len(em_rows)
        em_rows.append(_emitter_row(em, bs))

    sensor, film = scene.sensor, scene.sensor.film
    cam = camera_row(sensor.to_world, sensor.fov, sensor.fov_axis, film.width, film.height,
                     sensor.near_clip, sensor.far_clip)
    cam_med = meds(sensor.medium)
    materials = _material_rows(mats.objs)
    media = np.array([_medium_row(m) for m in meds.objs], dtype=np.float64).reshape(-1, L.MED_WIDTH)
    c = np.ascontiguousarray
    # the table's write flag and memory order name the BSDF families it holds: kernels compiled
    # for it leave the others out (kernels/bsdf/tiers.py)
    materials = tiered_table(materials)
    return SceneArrays(
        prims=c(rows), prim_info=c(info), prim_area=c(areas), nodes=nodes, node_info=node_info,
        materials=materials, media=c(media),
        emitters=c(np.array(em_rows, dtype=np.float64).reshape(-1, li.EM_WIDTH)),
        em_prims=np.array(em_prims, dtype=np.int32), em_cdf=np.array(em_cdf, dtype=np.float64),
        camera=cam, bsphere=bs, env=env, camera_medium=cam_med)
