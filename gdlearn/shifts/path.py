"""A light-transport path stored as arrays of vertices, and the measure conversions every shift needs.

Every shift mapping (STAR, Hua et al. 2019, Sec. 3) reads a base path and writes an offset path. To
stay numba-friendly (no jitclass) a path is a tuple of contiguous arrays, one row per vertex,
vertex 0 on the sensor (or the light, for a light subpath):

========== ============ =====================================================================
field      shape/dtype  meaning
========== ============ =====================================================================
pos        (n, 3) f8    world position
ng         (n, 3) f8    geometric normal; (0, 0, 0) at a medium vertex or a point sensor/light
ns         (n, 3) f8    shading normal: the z axis of the local frame (``vec.coordinate_system``)
mat        (n,) i4      material row index (-1: none, e.g. sensor, medium vertex)
med        (n,) i4      medium index the path travels in after the vertex (-1: vacuum)
vclass     (n,) i4      ``layout.V_DIFFUSE / V_GLOSSY / V_SPECULAR / V_MEDIUM``
pdf_sa     (n,) f8      solid-angle density with which the direction *leaving* the vertex was
                        sampled (for a delta lobe: the discrete lobe probability)
pdf_area   (n,) f8      area density of the *next* vertex: pdf_sa * |cos theta_next| / d^2
========== ============ =====================================================================

The length (number of valid vertices) travels beside the tuple: arrays are allocated once with a
maximum length and reused, so a kernel never allocates per sample.

Measure conversions (Veach 1997, Eq. 8.10): an area density p_A at y, reached from x along a
segment of length d, relates to the solid-angle density at x by ``p_A = p_w |cos theta_y| / d^2``.
A zero normal stands for a medium vertex, whose "cosine" is 1 (the volumetric path integral
measures volume, not area, there).
"""
import math

import numpy as np


from gdlearn.kernels import vec
from gdlearn.kernels.jit import block, ir_inline

PATH_FIELDS = ("pos", "ng", "ns", "mat", "med", "vclass", "pdf_sa", "pdf_area")


def new_path(max_vertices: int):
    """Allocate an empty path of capacity ``max_vertices`` (a tuple in :data:`PATH_FIELDS` order)."""
    if int(max_vertices) < 1:
        raise ValueError(f"new_path: max_vertices must be >= 1, got {max_vertices!r}; "
                         "fix: pass the maximum path depth + 1")
    n = int(max_vertices)
    return (np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)),
            np.full(n, -1, np.int32), np.full(n, -1, np.int32), np.zeros(n, np.int32),
            np.zeros(n), np.zeros(n))


@block
def set_vertex(path, i, p, ng, ns, mat, med, vclass, pdf_sa):
    """Write vertex ``i`` (pdf_area is filled later by :func:`fill_area_pdfs`)."""
    pos, png, pns, pmat, pmed, pvc, psa, _ = path
    for k in range(3):
        pos[i, k] = p[k]
        png[i, k] = ng[k]
        pns[i, k] = ns[k]
    pmat[i] = mat
    pmed[i] = med
    pvc[i] = vclass
    psa[i] = pdf_sa


@ir_inline
def get_pos(path, i):
    p = path[0]
    return (p[i, 0], p[i, 1], p[i, 2])


@ir_inline
def get_ng(path, i):
    p = path[1]
    return (p[i, 0], p[i, 1], p[i, 2])



@block
def copy_path(src, dst, n):
    """Copy the first n vertices of src into dst (the offset path starts as the base path)."""
    _copy_rows(src[0], dst[0], n)
    _copy_rows(src[1], dst[1], n)
    _copy_rows(src[2], dst[2], n)
    dst[3][:n] = src[3][:n]
    dst[4][:n] = src[4][:n]
    dst[5][:n] = src[5][:n]
    dst[6][:n] = src[6][:n]
    dst[7][:n] = src[7][:n]


@ir_inline
def _copy_rows(a, b, n):
    for i in range(n):
        for k in range(3):
            b[i, k] = a[i, k]


@ir_inline
def abs_cos(n, w):
    """|cos| between a unit direction and a normal; 1 for a medium vertex (zero normal)."""
    if n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0:
        return 1.0
    return abs(vec.dot(n, w))


@block
def geometry_term(x, nx, y, ny):
    """G(x, y) = |cos theta_x| |cos theta_y| / |x - y|^2 (visibility not included); 0 if x == y."""
    d = vec.sub(y, x)
    d2 = vec.dot(d, d)
    if not d2 > 0.0:
        return 0.0
    w = vec.scale(d, 1.0 / math.sqrt(d2))
    return abs_cos(nx, w) * abs_cos(ny, w) / d2


@block
def solid_angle_to_area(pdf_sa, x, y, ny):
    """Area density at y of a direction sampled at x with solid-angle density pdf_sa (Veach Eq. 8.10)."""
    d = vec.sub(y, x)
    d2 = vec.dot(d, d)
    if not d2 > 0.0:
        return 0.0
    return pdf_sa * abs_cos(ny, vec.scale(d, 1.0 / math.sqrt(d2))) / d2


@block
def fill_area_pdfs(path, n):
    """pdf_area[i] = density of vertex i+1 in the area measure, from pdf_sa[i] (last entry: 0)."""
    psa, pa = path[6], path[7]
    for i in range(n - 1):
        pa[i] = solid_angle_to_area(psa[i], get_pos(path, i), get_pos(path, i + 1), get_ng(path, i + 1))
    if n > 0:
        pa[n - 1] = 0.0


@block
def jacobian_solid_angle_to_area(j_sa, x_b, y_b, ny_b, x_o, y_o, ny_o):
    """Area-measure Jacobian |dy'/dy| of a shift whose direction map at x has solid-angle Jacobian
    j_sa = |dw'/dw| (base segment x_b -> y_b, offset segment x_o -> y_o, x_b and x_o held fixed).

    dA = d^2 / |cos theta_y| dw on both paths, hence
    ``|dy'/dy| = j_sa * (|cos theta_y| / d^2) / (|cos theta'_y| / d'^2)``.
    This is GPM (Hua et al. 2017) Eq. 4, J = J_w [G(z_i, z_i+1) / G(z'_i, z'_i+1)] * (cosine ratio
    at z_i): the G ratio carries the cosines at both ends, and the cosine factor at z_i must cancel
    the one inside G, i.e. it is cos(n'_i, z'_i->z'_i+1) / cos(n_i, z_i->z_i+1). (The plain-text
    extraction of Eq. 4 prints that ratio upside down; the finite-difference test in
    tests/test_shifts_halfvector.py checks the form used here.) Returns 0 for a degenerate segment.
    """
    db = vec.sub(y_b, x_b)
    do = vec.sub(y_o, x_o)
    db2 = vec.dot(db, db)
    do2 = vec.dot(do, do)
    if not (db2 > 0.0 and do2 > 0.0):
        return 0.0
    cb = abs_cos(ny_b, vec.scale(db, 1.0 / math.sqrt(db2)))
    co = abs_cos(ny_o, vec.scale(do, 1.0 / math.sqrt(do2)))
    if not co > 0.0:
        return 0.0          # grazing offset segment: caller treats as failed shift
    return j_sa * (cb / db2) * (do2 / co)
