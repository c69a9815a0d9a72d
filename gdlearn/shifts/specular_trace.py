"""A specular chain traced as a light path would trace it, and the relaxed acceptance of a manifold
walk (Gruson et al. 2018, Sec. 6.1; PHOTONS.md Sec. 5.4, "Relaxed manifold exploration").

:func:`traced_chain` starts at x_0, leaves towards the walk's first vertex X[0] and obeys every event
of the chain exactly: at vertex j the half vector is the base's (``targets``, the tangential
components in the vertex's frame; 0 for a perfect mirror or dielectric), the outgoing direction
follows from it by reflection or refraction (``gdlearn.shifts.halfvector.outgoing``, as the
half-vector copy computes it), and the next vertex is where that
ray meets the next chain shape. Only the analytic shapes are hit, not the scene: the caller checks
the chain's visibility.

A Newton iterate of the walk (``gdlearn.shifts.manifold.manifold_walk``) joins x_0 to its
endpoint with every vertex on its shape but its half vectors off by the residual; the traced chain
is the light path it stands for, whose end misses the target. Gruson et al. accept the walk as soon
as that end lies in the offset photon's kernel: within r of the photon b' *and* of the offset
gather point d' (the reference code's ``max(|x_last - b'|^2, |x_last - d'|^2) < r^2``). The photon
is then evaluated at b' with the traced chain, so only the last vertex's event is off, by at most
the angle r subtends from it. Biased, and consistent: the acceptance tightens as the radius
shrinks (Sec. 7). At a volume photon the traced end is the point of the last ray nearest b'.
"""
import math

from gdlearn.kernels import vec
from gdlearn.kernels.jit import block, inlined
from gdlearn.shifts.halfvector import outgoing
from gdlearn.shifts.manifold_shapes import SH_N, SH_P, SH_R, SH_TYPE, SHAPE_PLANE, _v3, shape_contains, shape_frame

ZERO3 = (0.0, 0.0, 0.0)
#: a shape hit closer than this fraction of the distance scale is the ray's own origin (the second
#: vertex of a chain on one sphere starts on it)
SELF_HIT = 1e-9


@inlined
def shape_hit(shapes, j, o, d):
    """The distance along the ray (o, unit d) to chain shape j, past o's own surface; inf if none."""
    c = _v3(shapes, j, SH_P)
    oc = vec.sub(o, c)
    if int(shapes[j, SH_TYPE]) == SHAPE_PLANE:
        den = vec.dot(d, _v3(shapes, j, SH_N))
        if den == 0.0:
            return math.inf
        t = -vec.dot(oc, _v3(shapes, j, SH_N)) / den
        return t if t > SELF_HIT * vec.norm(oc) else math.inf
    rad = shapes[j, SH_R]
    b = vec.dot(oc, d)
    disc = b * b - (vec.dot(oc, oc) - rad * rad)
    if not disc >= 0.0:
        return math.inf
    s = math.sqrt(disc)
    eps = SELF_HIT * (abs(b) + rad)
    if -b - s > eps:
        return -b - s
    if -b + s > eps:
        return -b + s
    return math.inf


@block
def traced_chain(x0, X, shapes, etas, refract, targets, k, Xt):
    """Xt[:k] <- the chain a light path from x0 through X[0] takes with every half vector at its
    target (module docstring). Returns (ok, the direction leaving Xt[k - 1]); not ok where an event
    is impossible or the ray misses the next shape."""
    prev = x0
    x = _v3(X, 0, 0)
    w = ZERO3
    for j in range(k):
        Xt[j, 0], Xt[j, 1], Xt[j, 2] = x[0], x[1], x[2]
        s, t, n = shape_frame(shapes, j, x)
        hx, hy = targets[j, 0], targets[j, 1]
        hz2 = 1.0 - hx * hx - hy * hy
        if not hz2 > 0.0:
            return False, ZERO3
        wi = vec.to_local(vec.normalize(vec.sub(prev, x)), s, t, n)
        wo, _, ok = outgoing(wi, (hx, hy, math.sqrt(hz2)), etas[j] if refract[j] else 1.0, refract[j])
        if not ok:
            return False, ZERO3
        w = vec.normalize(vec.to_world(wo, s, t, n))
        if j == k - 1:
            break
        dist = shape_hit(shapes, j + 1, x, w)
        if not math.isfinite(dist):
            return False, ZERO3
        prev = x
        x = vec.add(x, vec.scale(w, dist))
        if not shape_contains(shapes, j + 1, x):
            return False, ZERO3
    return True, w


@block
def relaxed_accept(x0, X, xe, xg, r, shapes, etas, refract, targets, k, Xt):
    """Gruson et al.'s relaxed acceptance (module docstring): does the chain traced through X[0]
    end within r of the endpoint xe (the offset photon b') and of xg (the offset gather point d')?
    Xt[:k] holds the traced chain."""
    ok, w = traced_chain(x0, X, shapes, etas, refract, targets, k, Xt)
    if not ok:
        return False
    a = _v3(Xt, k - 1, 0)
    t = vec.dot(vec.sub(xe, a), w)
    if not t > 0.0:
        return False
    end = vec.add(a, vec.scale(w, t))
    de, dg = vec.sub(end, xe), vec.sub(end, xg)
    return vec.dot(de, de) < r * r and vec.dot(dg, dg) < r * r
