"""Path reconnection (STAR, Hua et al. 2019, Sec. 3.3; Kettunen et al. 2015).

The partial offset path (x'_0 ... x'_b) is joined to the base path's next vertex y = x_{b+1}; every
vertex after y is shared. In the area measure the shifted vertex is y itself, so the Jacobian is

    |dy'/dy| = 1                                         (STAR Sec. 3.3, area measure)

In the solid-angle measure of the direction leaving x_b (what a path tracer samples), the same shift
maps the base direction w = (y - x_b)/|y - x_b| to w' = (y - x'_b)/|y - x'_b| and

    |dw'/dw| = (|cos theta'_y| / |x'_b - y|^2) / (|cos theta_y| / |x_b - y|^2)
             = |cos theta'_y| / |cos theta_y| * |x_b - y|^2 / |x'_b - y|^2     (solid-angle form)

with theta_y, theta'_y the angles at y between its normal and the base / offset segment
(dA_y = d^2 / |cos theta_y| dw, taken on both paths). This is GPM (Hua et al. 2017) Eq. 4's change
of measure solved for J_w with the area Jacobian set to 1 (see path.jacobian_solid_angle_to_area,
which turns this J_w back into exactly 1). A medium vertex y (zero normal) has cosine 1.

Reconnection is allowed only when x_b, x'_b and y are connectable (diffuse, glossy above the
roughness threshold, or medium; :func:`connectable`): at a specular vertex the reconnected direction
almost surely has zero BSDF. Visibility of the new segment x'_b -> y is the caller's ray query.

Short segments (gdlearn's guard, not the STAR's; :func:`far_enough`). The distance ratio
|x_b - y|^2 / |x'_b - y|^2 is unbounded when y lies close to x_b or x'_b compared with the shift's
own displacement delta = |x_b - x'_b|: in a dense medium (mean free path 0.4 in the medium cube,
a pixel's footprint 0.01-0.05) the next scattering vertex is often that close, and on surfaces the
next vertex is where a box meets the floor or a wall meets the ceiling; the offset's contribution
then swings by factors of 10 around the base's. Requiring both |x_b - y| and
|x'_b - y| >= c delta bounds the ratio: each length is within delta of the other, so

    (c / (c + 1))^2  <=  |x_b - y|^2 / |x'_b - y|^2  <=  ((c + 1) / c)^2,

[0.44, 2.25] for c = 2 (:data:`MIN_DISTANCE_RATIO`). The rule reads x_b and x'_b alike, so the
backward shift makes the same decision; a step that does not reconnect replays instead. Both mixed
kernels apply it, forward and in their reversibility checks (``gpt_surface.mixed``,
``gpt_volume.mixed``); Kettunen et al.'s ``halfvector+reconnection``, which has no replay to fall
back on, keeps its published rule.
"""
import math


from gdlearn.kernels import layout as L
from gdlearn.kernels import vec
from gdlearn.shifts.path import abs_cos
from gdlearn.kernels.jit import block, ir_inline, leaf


@ir_inline
def connectable(vclass):
    """True for vertex classes a reconnection may touch (STAR Sec. 3.3: 'diffuse enough')."""
    return vclass == L.V_DIFFUSE or vclass == L.V_GLOSSY or vclass == L.V_MEDIUM


#: c of the short-segment guard (module docstring): the reconnection's distance ratio stays in
#: [0.44, 2.25]. On the four media scenes (benchmarks/README.md, issue 20) c = 1.5, 2, 3 at 48^2 and
#: c = 2, 4 at 128^2 gave the same gradient errors within their standard errors; on the four surface
#: scenes c = 2 lowered gpt's gradient error by 2-6 % at 128^2.
MIN_DISTANCE_RATIO = 2.0


@leaf
def far_enough(x_b, x_b_offset, y):
    """Both segments x_b -> y and x'_b -> y at least MIN_DISTANCE_RATIO |x_b - x'_b| long (module
    docstring); symmetric in x_b and x'_b."""
    e = vec.sub(x_b, x_b_offset)
    lim = MIN_DISTANCE_RATIO * MIN_DISTANCE_RATIO * vec.dot(e, e)
    d = vec.sub(y, x_b)
    do = vec.sub(y, x_b_offset)
    return vec.dot(d, d) >= lim and vec.dot(do, do) >= lim


@block
def can_reconnect(class_b, class_b_offset, class_y):
    """Reconnection x'_b -> y is admissible (and, being symmetric in base and offset, reversible)."""
    return connectable(class_b) and connectable(class_b_offset) and connectable(class_y)


@leaf
def reconnection_jacobian_solid_angle(x_b, x_b_offset, y, n_y):
    """|dw'/dw| of the reconnection in the solid-angle measure at x_b (the solid-angle form in the
    module docstring: Jacobian 1 in area, STAR Sec. 3.3, times dA = d^2/|cos| dw on both paths).
    Returns 0 when a segment is degenerate or grazes y (then the shift fails)."""
    d = vec.sub(y, x_b)
    do = vec.sub(y, x_b_offset)
    d2 = vec.dot(d, d)
    do2 = vec.dot(do, do)
    if not (d2 > 0.0 and do2 > 0.0):
        return 0.0
    c = abs_cos(n_y, vec.scale(d, 1.0 / math.sqrt(d2)))
    co = abs_cos(n_y, vec.scale(do, 1.0 / math.sqrt(do2)))
    if not c > 0.0:
        return 0.0
    return (co / c) * (d2 / do2)


@leaf
def reconnect(x_b, x_b_offset, y, n_y):
    """Shift the segment x_b -> y to x'_b -> y.

    Returns ``(w_offset, dist_offset, jacobian_area, jacobian_solid_angle, ok)``: the world direction
    from x'_b to y and its length, the area-measure Jacobian (1) and its solid-angle form. ``ok`` is
    False (Jacobians 0) when x'_b coincides with y or the offset segment grazes y (cos theta'_y = 0:
    zero contribution and an irreversible shift, STAR Sec. 3.5).
    """
    do = vec.sub(y, x_b_offset)
    do2 = vec.dot(do, do)
    if not (do2 > 0.0) or not math.isfinite(do2):
        return (0.0, 0.0, 0.0), 0.0, 0.0, 0.0, False
    dist = math.sqrt(do2)
    w = vec.scale(do, 1.0 / dist)
    if not abs_cos(n_y, w) > 0.0:
        return w, dist, 0.0, 0.0, False
    j_sa = reconnection_jacobian_solid_angle(x_b, x_b_offset, y, n_y)
    if not (j_sa > 0.0 and math.isfinite(j_sa)):
        return w, dist, 0.0, 0.0, False
    return w, dist, 1.0, j_sa, True
