"""Manifold exploration shift (Jakob & Marschner 2012; STAR, Hua et al. 2019, Sec. 3.4; GPM 2017
Eq. 7-8): a Newton walk on half-vector constraints moves a specular chain x_1 .. x_k (k = 1..3)
so that it joins two fixed endpoints x_0 (the shifted connectable vertex x'_b) and x_{k+1} (the
base path's next connectable vertex x_c).

Constraints. At chain vertex j the generalised half vector h_j of (w_i = x_{j-1} - x_j, w_o =
x_{j+1} - x_j), expressed in the vertex's local frame (s, t, n), must keep the base path's tangential
components: c_j = (h_j . s, h_j . t) - o_j = 0, with o_j = 0 for a perfect mirror / dielectric
(Jakob & Marschner 2012, Sec. 4; the half vector as in halfvector.py, Walter et al. 2007). The 2k
unknowns are the chain vertices moved on their surfaces in 2-D charts.

Walk. Start from the base chain (the offset endpoint moved by ~a pixel: the base is an excellent
initial guess) -- or, where the moving endpoint is x_e and the sensitivity A^-1 B is at hand (a
photon's chain, :func:`predicted_walk`), from the chain's first-order prediction; each iteration
takes the Newton step dX = -A^-1 C, A = dC/dX; a step that leaves a surface, flips a reflection /
refraction side or does not reduce |C| is rejected and halved (step halving), at most
``max_halvings`` times. The walk stops when max |c_j| < ``tol`` or after ``max_iter`` iterations
(default 5, the GPM and volumetric papers' choice; Mitsuba uses 20) and reports failure otherwise;
a relaxed walk also stops at the first iterate whose traced light path ends in the offset photon's
kernel (Gruson et al. 2018's relaxed acceptance, :mod:`gdlearn.shifts.specular_trace`).
An unreachable target (the solution is off a finite surface, needs total internal reflection, or
is not found in the budget) is a failure flag, never an exception.

Jacobian (specular chain, GPM Eq. 7-8): the base path's free variable is x_1 (sampled from x_b); the
offset's is x'_1. With x_c shared, |dx'_1/dx_1| = |dx'_1/dx_c| (offset, x'_b fixed) * |dx_c/dx_1|
(base, x_b fixed) = |det D'| / |det D|, where D = dx_1/dx_c = rows of -A^-1 B (implicit function
theorem on C(X; x_c) = 0, B = dC/dx_c). |det D| is the ratio of geometry terms of Eq. 8,
G(x_b .. x_c) / G(x_b, x_1). A and B are the constraints' derivatives in closed form
(:mod:`gdlearn.shifts.manifold_constraints`: a plane's frame is fixed, a sphere's turns with its
normal), exact to round-off, for the walk's steps and for Eq. 8 alike. (Finite differences took
4(k + 1) evaluations of the constraints for A and B, 2k for a step's A; in closed form G-BRE's
walks on the volume caustic take a quarter less time, benchmarks/README.md, "The walk's
derivatives in closed form".)

Geometry of the chain: each chain vertex lies on an analytic surface given as a row of ``shapes``
(``SH_*`` columns): a plane quad (point, normal, two tangent axes, half extents; +-inf for an
unbounded plane) or a sphere (centre, radius; normal outward, local frame
``vec.coordinate_system(n)``). A triangle is a plane quad row bounded by its caller's check.
Visibility along the moved segments is the caller's ray query. The end vertex x_c must lie on a
surface (a medium end vertex would need a 3-D chart); glossy chains moved as if specular (GPM Eq.
9-10, with the half-vector reparameterisation of the Jacobian) are not implemented.
"""
import math

import numpy as np

from gdlearn.kernels import vec
from gdlearn.kernels.jit import block, inlined

from gdlearn.shifts.manifold_constraints import constraint_jacobian, constraints  # noqa: F401
from gdlearn.shifts.specular_trace import relaxed_accept
from gdlearn.shifts.manifold_shapes import (SH_EXT, SH_N, SH_P, SH_R, SH_TYPE, SH_U, SH_V, SH_WIDTH,  # noqa: F401
                                         SHAPE_PLANE, SHAPE_SPHERE, _v3, plane_row, shape_chart, sphere_row)

MAX_ITER = 5
MAX_HALVINGS = 10
TOL = 1e-12


@inlined
def _max_abs(a, m):
    r = 0.0
    for i in range(m):
        r = max(r, abs(a[i]))
    return r


@block
def solve_linear(A, B, m, nrhs):
    """Solve A Z = B in place (Gaussian elimination, partial pivoting); Z overwrites B. False if
    A is singular to working precision (numba's np.linalg.solve would raise instead)."""
    scale = 0.0
    for i in range(m):
        for c in range(m):
            scale = max(scale, abs(A[i, c]))
    if not scale > 0.0 or not math.isfinite(scale):
        return False
    for c in range(m):
        p = c
        for r in range(c + 1, m):
            if abs(A[r, c]) > abs(A[p, c]):
                p = r
        if not abs(A[p, c]) > 1e-13 * scale:
            return False
        for q in range(m):
            A[c, q], A[p, q] = A[p, q], A[c, q]
        for q in range(nrhs):
            B[c, q], B[p, q] = B[p, q], B[c, q]
        for r in range(c + 1, m):
            f = A[r, c] / A[c, c]
            for q in range(c, m):
                A[r, q] -= f * A[c, q]
            for q in range(nrhs):
                B[r, q] -= f * B[c, q]
    for c in range(m - 1, -1, -1):
        for q in range(nrhs):
            s = B[c, q]
            for r in range(c + 1, m):
                s -= A[c, r] * B[r, q]
            B[c, q] = s / A[c, c]
    return True


@block
def chain_length_scale(x0, X, xe, k):
    total = vec.norm(vec.sub(_v3(X, 0, 0), x0)) + vec.norm(vec.sub(xe, _v3(X, k - 1, 0)))
    for j in range(k - 1):
        total += vec.norm(vec.sub(_v3(X, j + 1, 0), _v3(X, j, 0)))
    return total / (k + 1)


@inlined
def _moved(X, dX, lam, shapes, k, Xn):
    for j in range(k):
        p = shape_chart(shapes, j, _v3(X, j, 0), lam * dX[2 * j, 0], lam * dX[2 * j + 1, 0])
        Xn[j, 0], Xn[j, 1], Xn[j, 2] = p[0], p[1], p[2]


@inlined
def _copy_chain(dst, src, k):
    """dst[:k] = src[:k] for a (k x 3) chain, as a loop. A slice assignment compiles numba's
    shape check with its error message's string formatting in every specialisation (kernels.jit:
    ~25 s of G-VPM's cold compile)."""
    for j in range(k):
        dst[j, 0], dst[j, 1], dst[j, 2] = src[j, 0], src[j, 1], src[j, 2]


@inlined
def _norm2(a, m):
    s = 0.0
    for i in range(m):
        s += a[i] * a[i]
    return math.sqrt(s)


@block
def manifold_walk(x0, xe, X, shapes, etas, refract, targets, k, max_iter, max_halvings, tol, relax):
    """Newton walk (module docstring) moving the chain X (k x 3, updated in place, start = base
    chain) until it joins x0 and xe. Returns ``(ok, iterations, residual)`` (max |c_j|).

    ``relax``: None (the exact walk; numba compiles no relaxed code for it), or (xg, r) for
    Gruson et al. 2018's relaxed acceptance (:func:`gdlearn.shifts.specular_trace.relaxed_accept`,
    r > 0; r = 0 walks exactly): an iterate whose traced chain ends within r of xe and of the
    gather point xg is accepted, and X becomes that traced chain."""
    m = 2 * k
    C = np.empty(m)
    Cn = np.empty(m)
    A = np.empty((m, m))
    dX = np.empty((m, 1))
    Xn = X.copy()
    if not constraints(x0, X, xe, shapes, etas, refract, targets, k, C):
        return False, 0, math.inf
    r = _max_abs(C, m)
    for it in range(max_iter):
        if r < tol:
            return True, it, r
        # Xn serves as the relaxed test's scratch until the step below fills it
        if relax is not None:
            if _relaxed(x0, X, xe, relax, shapes, etas, refract, targets, k, Xn):
                return True, it, r
        # A alone (with_b False): the endpoint's normal and B are not read, xe and A stand in for them
        if not constraint_jacobian(x0, X, xe, xe, shapes, etas, refract, k, A, A, False):
            return False, it, r
        for i in range(m):
            dX[i, 0] = -C[i]
        if not solve_linear(A, dX, m, 1):
            return False, it, r
        lam = 1.0
        accepted = False
        n0 = _norm2(C, m)
        for _ in range(max_halvings + 1):
            _moved(X, dX, lam, shapes, k, Xn)
            if constraints(x0, Xn, xe, shapes, etas, refract, targets, k, Cn) and _norm2(Cn, m) < n0:
                accepted = True
                break
            lam *= 0.5                      # step halving on rejection
        if not accepted:
            return False, it + 1, r
        _copy_chain(X, Xn, k)                # rows k.. of Xn are X's: a copy of X never written there
        for i in range(m):
            C[i] = Cn[i]
        r = _max_abs(C, m)
    if relax is not None:
        if r >= tol and _relaxed(x0, X, xe, relax, shapes, etas, refract, targets, k, Xn):
            return True, max_iter, r
    return r < tol, max_iter, r


@inlined
def _relaxed(x0, X, xe, relax, shapes, etas, refract, targets, k, Xt):
    """The relaxed acceptance of iterate X (``relax`` = (xg, r), r > 0); X <- its traced chain."""
    xg, rr = relax
    if not (rr > 0.0 and relaxed_accept(x0, X, xe, xg, rr, shapes, etas, refract, targets, k, Xt)):
        return False
    _copy_chain(X, Xt, k)
    return True


@block
def endpoint_sensitivity(x0, X, xe, ne, shapes, etas, refract, targets, k, A, S):
    """``(|det dx_1/dx_e|, ok)`` with x0 fixed: the generalised-geometry ratio of GPM Eq. 8,
    G(x_0 .. x_e) / G(x_0, x_1), from the implicit function theorem on the constraints,
    C(X(x_e), x_e) = 0 => dX/dx_e = -A^-1 B. Leaves S = A^-1 B (2k x 2, chart coordinates of the
    chain per chart coordinate of x_e in the plane of normal ne), which :func:`predicted_start`
    takes; A (2k x 2k) is scratch."""
    m = 2 * k
    if not constraint_jacobian(x0, X, xe, ne, shapes, etas, refract, k, A, S, True):
        return 0.0, False
    if not solve_linear(A, S, m, 2):
        return 0.0, False
    d = abs(S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0])     # the sign of -A^-1 B does not matter
    if not (d > 0.0 and math.isfinite(d)):
        return 0.0, False
    return d, True


@block
def chain_endpoint_det(x0, X, xe, ne, shapes, etas, refract, targets, k):
    """:func:`endpoint_sensitivity`'s determinant alone."""
    m = 2 * k
    return endpoint_sensitivity(x0, X, xe, ne, shapes, etas, refract, targets, k, np.empty((m, m)),
                                np.empty((m, 2)))


@block
def predicted_start(X, xe, ne, xe_new, S, shapes, k, Xp):
    """Xp <- the chain joining x0 to ``xe_new`` to first order: X moved in its charts by
    dX = -S (e . s, e . t), e = xe_new - xe, (s, t) the chart of x_e (normal ne) and S = A^-1 B of
    :func:`endpoint_sensitivity` at X. Started there, a walk's error is O(``|e|^2``) instead of
    O(``|e|``): Newton's quadratic convergence then skips about one step (benchmarks/README.md,
    "A walk that starts where the chain will be")."""
    s, t = vec.coordinate_system(ne)
    e = vec.sub(xe_new, xe)
    u, v = vec.dot(e, s), vec.dot(e, t)
    for j in range(k):
        p = shape_chart(shapes, j, _v3(X, j, 0), -(S[2 * j, 0] * u + S[2 * j, 1] * v),
                        -(S[2 * j + 1, 0] * u + S[2 * j + 1, 1] * v))
        Xp[j, 0], Xp[j, 1], Xp[j, 2] = p[0], p[1], p[2]


@block
def predicted_walk(x0, X, xe, ne, xe_new, S, shapes, etas, refract, targets, k, Xo, relax):
    """Xo <- the chain X walked to join x0 and ``xe_new``, started at :func:`predicted_start` -- or
    at X itself where the prediction leaves a finite surface (or another event's side). A
    deterministic function of the base chain and the new endpoint, as a shift must be. Returns
    :func:`manifold_walk`'s ``(ok, iterations, residual)``; ``relax`` as there."""
    predicted_start(X, xe, ne, xe_new, S, shapes, k, Xo)
    ok, it, r = manifold_walk(x0, xe_new, Xo, shapes, etas, refract, targets, k, MAX_ITER, MAX_HALVINGS, TOL, relax)
    if ok or it > 0 or r < math.inf:
        return ok, it, r
    _copy_chain(Xo, X, k)                   # the predicted start is invalid: the plain walk
    return manifold_walk(x0, xe_new, Xo, shapes, etas, refract, targets, k, MAX_ITER, MAX_HALVINGS, TOL, relax)


@block
def half_vector_targets(x0, X, xe, shapes, etas, refract, k, targets):
    """Fill targets (k x 2) with the base chain's tangential half-vector components (0 at a perfect
    specular vertex up to round-off); False if the base chain itself is invalid."""
    zeros = np.zeros((k, 2))
    c = np.empty(2 * k)
    if not constraints(x0, X, xe, shapes, etas, refract, zeros, k, c):
        return False
    for j in range(k):
        targets[j, 0] = c[2 * j]
        targets[j, 1] = c[2 * j + 1]
    return True


@block
def _walks_back(x_b, X_base, x_c, Xo, shapes, etas, refract, targets, k, max_iter):
    """True if the walk from the offset chain back to x_b returns to the base chain: near a caustic
    several chains join the same endpoints and the shift would not be invertible there."""
    Xb = Xo.copy()
    ok, _, _ = manifold_walk(x_b, x_c, Xb, shapes, etas, refract, targets, k, max_iter,
                             MAX_HALVINGS, TOL, None)
    return ok and same_chain(x_b, X_base, x_c, Xb, k)


@block
def same_chain(x0, X, xe, Y, k):
    """Is the chain Y the chain X (x0 .. xe) to 1e-7 of its length scale? (A walk back that finds
    another chain joining the same endpoints: the shift is not invertible there.)"""
    tol = 1e-7 * chain_length_scale(x0, X, xe, k)
    for j in range(k):
        for c in range(3):
            if not abs(Y[j, c] - X[j, c]) <= tol:
                return False
    return True


@block
def manifold_shift(x_b, x_b_offset, X_base, x_c, n_c, shapes, etas, refract, k, X_out, max_iter,
                   check_reversible):
    """Shift the specular chain X_base (k x 3) between x_b and x_c to join x'_b and x_c.

    Returns ``(jacobian, ok, iterations)``: J = |dx'_1/dx_1| in the area measure (GPM Eq. 7-8, module
    docstring) and the offset chain in X_out. Failure (walk did not converge in ``max_iter``,
    unreachable target, singular constraints) returns J = 0 and ok = False. With
    ``check_reversible`` the backward walk must also lead back to the base chain (else ok = False:
    an irreversible shift, STAR Sec. 3.5); it doubles the cost.
    """
    if k < 1 or k > X_base.shape[0] or vec.dot(n_c, n_c) == 0.0:
        return 0.0, False, 0            # x_c must be a surface vertex (its 2-D chart is the measure)
    targets = np.empty((k, 2))
    if not half_vector_targets(x_b, X_base, x_c, shapes, etas, refract, k, targets):
        return 0.0, False, 0
    _copy_chain(X_out, X_base, k)
    Xo = X_out[:k]
    ok, iters, _ = manifold_walk(x_b_offset, x_c, Xo, shapes, etas, refract, targets, k,
                                 max_iter, MAX_HALVINGS, TOL, None)
    if not ok:
        return 0.0, False, iters
    det_b, ok_b = chain_endpoint_det(x_b, X_base, x_c, n_c, shapes, etas, refract, targets, k)
    det_o, ok_o = chain_endpoint_det(x_b_offset, Xo, x_c, n_c, shapes, etas, refract, targets, k)
    if not (ok_b and ok_o):
        return 0.0, False, iters
    j = det_o / det_b
    if not (j > 0.0 and math.isfinite(j)):
        return 0.0, False, iters
    if check_reversible and not _walks_back(x_b, X_base, x_c, Xo, shapes, etas, refract,
                                            targets, k, max_iter):
        return 0.0, False, iters
    return j, True, iters
