"""The half-vector constraints of a specular chain and their derivatives in closed form
(:mod:`gdlearn.shifts.manifold`'s walk; Jakob & Marschner 2012): C for the walk's residual, A =
dC/dX for its Newton steps and B = dC/dx_e for the endpoint sensitivity of GPM Eq. 8 (Hua et al.
2017). Both read a chain vertex's event the same way (:func:`vertex_event`), so a chain C calls
invalid is one A and B refuse too.

c_j = (h_j . s_j, h_j . t_j) - o_j depends on x_{j-1}, x_j and x_{j+1} only, so A is block
tridiagonal. Every column is a few dot products: a unit vector w = v / |v| changes by
dw = (I - w w^T) dv / |v|, the half vector h = sigma H / |H| of H = w_i + k w_o by
dh = (sigma / |H|) (I - h h^T) dH, and a sphere vertex's own move also turns its frame
(:func:`_frame_change`). Exact to round-off; tests/test_shifts_manifold.py checks them against
fourth-order central differences of :func:`constraints`.
"""
import math

from gdlearn.kernels import vec
from gdlearn.kernels.jit import block, inlined
from gdlearn.shifts.halfvector import half_vector
from gdlearn.shifts.manifold_shapes import SH_R, SH_TYPE, SHAPE_PLANE, _v3, shape_contains, shape_frame

_ZERO = (0.0, 0.0, 0.0)


@inlined
def vertex_event(x0, X, xe, shapes, etas, refract, j, k):
    """Chain vertex j's specular event, between x_{j-1} (x0 for j = 0) and x_{j+1} (xe for the
    last): (ok, its frame (s, t, n), w_i, w_o, l_i, l_o, the half vector in the local frame, k).
    Not ok where the vertex is off its surface, a direction is degenerate, the two directions lie
    on the wrong sides for its event (reflection or refraction), or the half vector is degenerate
    or on the wrong side of either direction."""
    no = (False, (_ZERO, _ZERO, _ZERO), _ZERO, _ZERO, 0.0, 0.0, _ZERO, 1.0)
    xj = _v3(X, j, 0)
    if not shape_contains(shapes, j, xj):
        return no
    prev = x0 if j == 0 else _v3(X, j - 1, 0)
    nxt = xe if j == k - 1 else _v3(X, j + 1, 0)
    s, t, n = shape_frame(shapes, j, xj)
    vi, vo = vec.sub(prev, xj), vec.sub(nxt, xj)
    wi, wo = vec.normalize(vi), vec.normalize(vo)
    wi_l, wo_l = vec.to_local(wi, s, t, n), vec.to_local(wo, s, t, n)
    side = wi_l[2] * wo_l[2]
    if (refract[j] and not side < 0.0) or (not refract[j] and not side > 0.0):
        return no
    h, kk, ok = half_vector(wi_l, wo_l, etas[j] if refract[j] else 1.0)
    if not ok or not (vec.dot(wi_l, h) * wi_l[2] > 0.0 and vec.dot(wo_l, h) * wo_l[2] > 0.0):
        return no
    return True, (s, t, n), wi, wo, vec.norm(vi), vec.norm(vo), h, kk


@inlined
def constraints(x0, X, xe, shapes, etas, refract, targets, k, out):
    """Fill out[0:2k] with c_j (module docstring); False if an event is invalid (:func:`vertex_event`)."""
    for j in range(k):
        ok, _, _, _, _, _, h, _ = vertex_event(x0, X, xe, shapes, etas, refract, j, k)
        if not ok:
            return False
        out[2 * j] = h[0] - targets[j, 0]
        out[2 * j + 1] = h[1] - targets[j, 1]
    return True


@inlined
def _frame_change(shapes, j, n, e):
    """(ds, dt): the first-order change of vertex j's frame (s, t) = ``vec.coordinate_system(n)``
    when the vertex moves by the tangent vector e. A plane's frame is fixed; on a sphere dn = e / R,
    and (s, t) is Duff et al. 2017's basis, a rational function of n differentiated term by term
    (a = -1 / (sign + n_z), b = n_x n_y a)."""
    if int(shapes[j, SH_TYPE]) == SHAPE_PLANE:
        return _ZERO, _ZERO
    rr = shapes[j, SH_R]
    dn = (e[0] / rr, e[1] / rr, e[2] / rr)
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    da = a * a * dn[2]
    db = (dn[0] * n[1] + n[0] * dn[1]) * a + n[0] * n[1] * da
    ds = (sign * (2.0 * n[0] * dn[0] * a + n[0] * n[0] * da), sign * db, -sign * dn[0])
    dt = (db, 2.0 * n[1] * dn[1] * a + n[1] * n[1] * da, -dn[1])
    return ds, dt


@inlined
def _transverse(w, e, scale):
    """scale (e - w (w . e)): the change of the unit vector w = v / |v| when v moves by e, times
    scale |v| (d normalize(v) = (I - w w^T) dv / |v|)."""
    we = vec.dot(w, e)
    return ((e[0] - w[0] * we) * scale, (e[1] - w[1] * we) * scale, (e[2] - w[2] * we) * scale)


@inlined
def _put_dc(M_, r, col, h, f, s, t, dH, ds, dt):
    """Rows r, r + 1 of column ``col`` of M_: the change of c = (h . s, h . t) for a change dH of
    H = w_i + k w_o and (ds, dt) of the frame; h = sigma H / |H|, so dh = f (dH - h (h . dH)) with
    f = sigma / |H|."""
    hd = vec.dot(h, dH)
    dh = ((dH[0] - h[0] * hd) * f, (dH[1] - h[1] * hd) * f, (dH[2] - h[2] * hd) * f)
    M_[r, col] = vec.dot(dh, s) + vec.dot(h, ds)
    M_[r + 1, col] = vec.dot(dh, t) + vec.dot(h, dt)


@block
def constraint_jacobian(x0, X, xe, ne, shapes, etas, refract, k, A, B, with_b):
    """A = dC/dX (2k x 2k: each chain vertex in its chart, the chart's axes being its frame's s, t)
    and, ``with_b``, B = dC/dx_e (2k x 2: x_e in the plane of normal ne, axes
    ``vec.coordinate_system(ne)``), in closed form. False where :func:`vertex_event` is not ok.

    c_j = (h_j . s_j, h_j . t_j) - o_j depends on x_{j-1}, x_j and x_{j+1} only (A is block
    tridiagonal, as in Jakob & Marschner 2012). With w_i = (x_{j-1} - x_j) / l_i,
    w_o = (x_{j+1} - x_j) / l_o, H = w_i + k w_o (k = 1, or the refraction's eta ratio) and
    h = sigma H / |H|: dh = (sigma / |H|) (I - h h^T) dH, dw = (I - w w^T) dx / l, and moving x_j itself
    also turns a sphere's frame (:func:`_frame_change`). The targets o_j are constants. Checked
    against fourth-order central differences of :func:`constraints` (tests/test_shifts_manifold.py)."""
    m = 2 * k
    for r in range(m):
        for c in range(m):
            A[r, c] = 0.0
        if with_b:
            B[r, 0] = 0.0
            B[r, 1] = 0.0
    for j in range(k):
        ok, (s, t, n), wi, wo, li, lo, hl, kk = vertex_event(x0, X, xe, shapes, etas, refract, j, k)
        if not (ok and li > 0.0 and lo > 0.0):
            return False
        prev = x0 if j == 0 else _v3(X, j - 1, 0)
        nxt = xe if j == k - 1 else _v3(X, j + 1, 0)
        h = vec.to_world(hl, s, t, n)
        H = (wi[0] + kk * wo[0], wi[1] + kk * wo[1], wi[2] + kk * wo[2])
        f = vec.dot(h, H) / vec.dot(H, H)                      # sigma / |H|
        r = 2 * j
        for a in range(2):
            e = s if a == 0 else t                             # x_j moves along its own chart
            gi, go = _transverse(wi, e, -1.0 / li), _transverse(wo, e, -kk / lo)
            ds, dt = _frame_change(shapes, j, n, e)
            _put_dc(A, r, r + a, h, f, s, t, vec.add(gi, go), ds, dt)
        if j > 0:                                              # x_{j-1} moves along its chart
            sp, tp, _ = shape_frame(shapes, j - 1, prev)
            for a in range(2):
                _put_dc(A, r, r - 2 + a, h, f, s, t, _transverse(wi, sp if a == 0 else tp, 1.0 / li), _ZERO, _ZERO)
        if j < k - 1:
            sn, tn, _ = shape_frame(shapes, j + 1, nxt)
            for a in range(2):
                _put_dc(A, r, r + 2 + a, h, f, s, t, _transverse(wo, sn if a == 0 else tn, kk / lo), _ZERO, _ZERO)
        elif with_b:                                           # x_e moves in the plane of normal ne
            se, te = vec.coordinate_system(ne)
            for a in range(2):
                _put_dc(B, r, a, h, f, s, t, _transverse(wo, se if a == 0 else te, kk / lo), _ZERO, _ZERO)
    return True
