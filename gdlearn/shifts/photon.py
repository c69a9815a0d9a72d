"""The photon half of GPM's hybrid shift (Hua et al. 2017, Sec. 4.2, Eq. 5-6; PHOTONS.md Sec. 2.4-2.5).

The base path is a light subpath y_0 ... y_{s-1} y_s (y_s the photon) merged with a camera subpath
at the gather point z_t. Once the camera subpath is shifted to the offset gather point z'_t, the
photon follows it:

* **Eq. 5**, the offset photon's target: the photon's position relative to the gather point,
  copied in the local tangent frames, ``y*_s = z'_t + M' M^-1 (y_s - z_t)`` (M, M' the shading
  frames at z_t and z'_t, :func:`offset_target`). The frames are Duff et al. 2017's branchless ones
  (``gdlearn.kernels.vec.coordinate_system``): continuous in the normal except where its z
  component changes sign, so neighbouring pixels on one flat surface get the same frame and y* is
  y_s translated by z'_t - z_t (across that seam the frames differ by a flip: less correlation, no
  bias).
* **Projection**: y'_s is the first surface the ray from y_{s-1} through y*_s hits (the caller
  traces it). The map y* -> y'_s keeps the direction from y_{s-1}, so it preserves solid angle
  there and (Eq. 6)

      ``|dy'_s / dy_s|`` = G(y_{s-1}, y*_s) / G(y_{s-1}, y'_s) = (cos*_ / d*^2) / (cos'_ / d'^2),

  cos* taken with the normal of y*'s plane -- the photon's own normal carried by the rigid map of
  Eq. 5 (the reference code takes the offset gather point's, the same for a photon on the gather
  point's plane) -- and cos' with the hit's normal; the cosine at y_{s-1} is common to both and
  cancels (:func:`projection_jacobian`).
  PHOTONS.md Sec. 2.4 notes the reference code drops this factor in its reconnection branch;
  here it is applied in every branch.
* **Reconnection** (Eq. 6 alone; the light subpath is completed by y_{s-1} -> y'_s when y_{s-1}
  is diffuse or glossy above the roughness threshold, or the emitter): the parent's scattering is
  re-evaluated towards y'_s. In ratio form, with the photon's power beta_s (its light subpath's
  f / p, every roulette and edge factor included),

      beta'_s = beta_s * [f_{s-1}(w') / f_{s-1}(w)] * (cos*_ / d*^2) / (cos_s / d^2),

  f the parent's cosine-weighted adjoint BSDF (or the emitter's profile, :func:`emission_profile`),
  w and w' the base and offset directions leaving it, cos_s and d the base photon's cosine and
  distance. The derivation: the offset contribution is ``f(T x) |dT/dx| / p(x)``; the light
  subpath's part of it is ``beta_{s-1} f'_{s-1} G(y_{s-1}, y'_s) |dy'_s/dy_s| / p_A(y_s)`` with
  ``p_A(y_s) = p_w(w) cos_s / d^2``, and ``G(y_{s-1}, y'_s) |dy'_s/dy_s| = cos'_{s-1} cos*_ / d*^2``.
* **MIS, Eq. 11** in area measure: only y_s changed on the light side, so the density ratio of
  the offset to the base path is ``p_w(w') / p_w(w) * (cos*_ / d*^2) / (cos_s / d^2)``
  (:func:`photon_geometry_ratio` is the second factor), times the camera side's ratio.
"""
import math

from gdlearn.kernels import vec
from gdlearn.kernels.jit import inlined
from gdlearn.kernels.lights import E_AREA, E_POINT, E_SPOT, EM_COS_CUTOFF, EM_TYPE, spot_falloff
from gdlearn.shifts.path import abs_cos


@inlined
def rotate(v, frame, frame_o):
    """``M' M^-1 v``: a vector carried from the frame ``(n, s, t)`` at z to the one at z' (Eq. 5's
    rotation; the photon's normal goes with it to y*)."""
    n, s, t = frame
    no, so, to = frame_o
    return vec.to_world(vec.to_local(v, s, t, n), so, to, no)


@inlined
def offset_target(y, z, frame, z_o, frame_o):
    """Eq. 5: ``y* = z' + M' M^-1 (y - z)`` with frames ``(n, s, t)`` at z and z' (world vectors)."""
    w = rotate((y[0] - z[0], y[1] - z[1], y[2] - z[2]), frame, frame_o)
    return (z_o[0] + w[0], z_o[1] + w[1], z_o[2] + w[2])


@inlined
def projection_jacobian(y_parent, y_star, n_star, y_hit, n_hit):
    """Eq. 6: ``|dy'/dy| = (|cos*| / d*^2) / (|cos'| / d'^2)`` for the projection of y* onto y' along
    the ray from ``y_parent`` (cosines with n_star at y*, n_hit at y'). 0 if a segment is degenerate
    or the hit is grazing (then the shift fails)."""
    a = vec.sub(y_star, y_parent)
    b = vec.sub(y_hit, y_parent)
    da = vec.dot(a, a)
    db = vec.dot(b, b)
    if not (da > 0.0 and db > 0.0):
        return 0.0
    ca = abs_cos(n_star, vec.scale(a, 1.0 / math.sqrt(da)))
    cb = abs_cos(n_hit, vec.scale(b, 1.0 / math.sqrt(db)))
    if not cb > 0.0:
        return 0.0
    return (ca / da) / (cb / db)


@inlined
def emission_profile(emitters, em, n0, d):
    """(value, pdf) of an emitter vertex y_0 sending light along ``d``: the directional factor of
    Le (cos theta for an area light, one-sided; 1 for a point light; the falloff for a spot) and the
    solid-angle density the light tracer samples d with (``gdlearn.photons.emit.sample_emission``).
    (0, 0) where the direction cannot be emitted or the emitter is a far one (directional,
    environment), which the shift does not handle."""
    et = int(emitters[em, EM_TYPE])
    if et == E_AREA:
        c = vec.dot(d, n0)
        if not c > 0.0:
            return 0.0, 0.0
        return c, c / math.pi
    if et == E_POINT:
        return 1.0, 0.25 / math.pi
    if et == E_SPOT:
        f = spot_falloff(emitters, em, d)
        if not f > 0.0:
            return 0.0, 0.0
        return f, 1.0 / (2.0 * math.pi * (1.0 - emitters[em, EM_COS_CUTOFF]))
    return 0.0, 0.0


@inlined
def photon_geometry_ratio(y_parent, y_base, n_base, y_star, n_star):
    """``(|cos*| / d*^2) / (|cos_s| / d^2)``: the factor the offset photon's power and the light side
    of the MIS ratio share (module docstring); 0 if degenerate. It is Eq. 6's ratio with the roles
    of the two points exchanged (y* in place of the projection, the base photon in place of y*)."""
    return projection_jacobian(y_parent, y_star, n_star, y_base, n_base)
