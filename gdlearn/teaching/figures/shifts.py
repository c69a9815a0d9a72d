"""The figures of the chapter "Shift mappings" (book/shifts.md): base paths in a 2-D cross-section
scene, their offset paths as gdlearn's shifts compute them, and how often each policy fails.

The shifts are the library's own -- :func:`gdlearn.shifts.reconnection.reconnect`,
:func:`gdlearn.shifts.halfvector.halfvector_copy_world`, :func:`gdlearn.shifts.manifold.manifold_shift`,
the policy's :func:`gdlearn.shifts.policy.choose_shift` -- so a drawing is the library's output. This
module only supplies what they need around them: a tiny analytic scene (floor, back wall, a sphere of
glass or mirror, an area light; everything cut by the plane y = 0, so paths stay in that plane and
draw in 2-D), a numpy ray caster for it, base paths made from "random numbers", and the driver that
walks a base path vertex by vertex and applies the action the policy chooses (STAR, Hua et al. 2019,
Sec. 3.5; Kettunen et al. 2015). Drawing: :mod:`gdlearn.teaching.figures.shifts_draw`.

A diffuse bounce samples its direction with ``sampling.square_to_cosine_hemisphere(u, 0.5)``: the
second number 0.5 keeps the direction in the section plane (Mitsuba's concentric map then gives
phi = 0 or pi), so "the random numbers" of a base path are one number per diffuse bounce. Glass
always refracts (total internal reflection excepted) and the mirror reflects, as a path tracer that
chose the transmitted lobe would.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gdlearn.kernels import layout as L
from gdlearn.kernels import sampling, vec
from gdlearn.shifts import manifold as M
from gdlearn.shifts import policy as P
from gdlearn.shifts.halfvector import halfvector_copy_world
from gdlearn.shifts.reconnection import reconnect

FLOOR, WALL, LIGHT, SPHERE, CEILING = 0, 1, 2, 3, 4
#: pseudo-surface of the last vertex of a failed offset whose ray left the scene (drawn 1.5 m out)
ESCAPED = -2
SURFACE_NAMES = ("floor", "wall", "light", "sphere", "ceiling")
#: relative distance tolerance for "the new segment reaches its target" (a visibility test)
VISIBLE_TOL = 1e-7


@dataclass(frozen=True)
class Section:
    """The cross-section scene (units: metres, y = 0 plane). ``sphere`` is "glass" or "mirror"."""
    sphere: str = "glass"
    eta: float = 1.5
    center: tuple = (0.6, 0.0, 1.0)
    radius: float = 0.6
    light: tuple = (0.25, 0.95, 3.0)          # x0, x1, height of the light (facing down)
    wall_x: float = 2.6
    top: float = 3.2
    floor_x0: float = -3.6
    camera: tuple = (-2.8, 0.0, 2.6)
    look_at: tuple = (0.4, 0.0, 0.5)
    fov_deg: float = 44.0
    pixels: int = 64

    def __post_init__(self):
        if self.sphere not in ("glass", "mirror"):
            raise ValueError(f"Section: sphere must be 'glass' or 'mirror', got {self.sphere!r}")
        if not (self.eta > 0 and self.radius > 0 and self.pixels > 0):
            raise ValueError("Section: eta, radius and pixels must be positive")


@dataclass
class Vertex:
    pos: np.ndarray
    normal: np.ndarray          # outward (sphere), facing the scene (planes); zero at the camera
    surface: int                # FLOOR / WALL / LIGHT / SPHERE, -1 for the camera, ESCAPED

    @property
    def vclass(self):
        return L.V_SPECULAR if self.surface == SPHERE else L.V_DIFFUSE


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def camera_direction(sc: Section, film: float) -> np.ndarray:
    """Direction of the camera ray through film coordinate ``film`` in [0, pixels) (top to bottom)."""
    fwd = unit(np.subtract(sc.look_at, sc.camera))
    angle = (0.5 - film / sc.pixels) * math.radians(sc.fov_deg)
    c, s = math.cos(angle), math.sin(angle)
    return unit([c * fwd[0] - s * fwd[2], 0.0, s * fwd[0] + c * fwd[2]])   # rotate in the x-z plane


def cast(sc: Section, o, d, tmin=1e-9):
    """First hit of the ray o + t d: ``(t, surface)``, or ``(inf, -1)`` if it leaves the scene."""
    best, surf = math.inf, -1
    if d[2] != 0.0:
        for z, s, lo, hi in ((0.0, FLOOR, sc.floor_x0, sc.wall_x), (sc.light[2], LIGHT, sc.light[0], sc.light[1]),
                             (sc.top, CEILING, sc.floor_x0, sc.wall_x)):
            t = (z - o[2]) / d[2]
            if tmin < t < best and lo <= o[0] + t * d[0] <= hi:
                best, surf = t, s
    if d[0] != 0.0:
        t = (sc.wall_x - o[0]) / d[0]
        if tmin < t < best and 0.0 <= o[2] + t * d[2] <= sc.top:
            best, surf = t, WALL
    oc = np.subtract(o, sc.center)
    b = float(np.dot(oc, d))
    disc = b * b - (float(np.dot(oc, oc)) - sc.radius ** 2)
    if disc >= 0.0:
        for t in (-b - math.sqrt(disc), -b + math.sqrt(disc)):
            if tmin * max(1.0, abs(t)) < t < best:
                best, surf = t, SPHERE
                break
    return best, surf


def vertex_at(sc: Section, p, surface) -> Vertex:
    n = {FLOOR: (0.0, 0.0, 1.0), WALL: (-1.0, 0.0, 0.0), LIGHT: (0.0, 0.0, -1.0), CEILING: (0.0, 0.0, -1.0)}.get(surface)
    n = unit(np.subtract(p, sc.center)) if surface == SPHERE else np.array(n)
    return Vertex(np.asarray(p, float), n, surface)


def specular_scatter(sc: Section, d, n):
    """Travel direction after the sphere: mirror reflection, or Snell refraction (outward normal n;
    total internal reflection reflects)."""
    c = -float(np.dot(d, n))
    if sc.sphere == "mirror":
        return unit(d + 2 * c * n)
    eta_ti, nn = (1.0 / sc.eta, n) if c > 0 else (sc.eta, -n)
    c = abs(c)
    s2 = eta_ti ** 2 * (1.0 - c * c)
    if s2 >= 1.0:
        return unit(d + 2 * float(np.dot(-d, nn)) * nn)
    return unit(eta_ti * d + (eta_ti * c - math.sqrt(1.0 - s2)) * nn)


def diffuse_direction(n, u):
    """Cosine-weighted direction (gdlearn's warp) in the section plane, from one random number u."""
    s, t = vec.coordinate_system(tuple(n))
    return np.array(vec.to_world(sampling.square_to_cosine_hemisphere(u, 0.5), s, t, tuple(n)))


class Path(list):
    """A base path (list of vertices) that keeps the random numbers it was traced with (``us``), so a
    replayed offset can read the numbers of bounces the base itself never made."""
    us: tuple = ()


def trace_base(sc: Section, film: float, us, max_vertices: int = 7, start=None):
    """A base path from the camera through ``film``: vertices until the light, an escape, or
    ``max_vertices``. ``us``: one random number per diffuse bounce. ``start`` = (o, d) overrides the
    camera ray (used for light-to-floor caustic paths). Returns a :class:`Path`."""
    o, d = (np.asarray(sc.camera, float), camera_direction(sc, film)) if start is None else start
    verts = Path([Vertex(np.asarray(o, float), np.zeros(3), -1)])
    verts.us = tuple(us)
    k = 0
    while len(verts) < max_vertices:
        t, s = cast(sc, o, d)
        if s < 0:
            break
        v = vertex_at(sc, o + t * d, s)
        verts.append(v)
        if s == LIGHT:
            break
        if s == SPHERE:
            d = specular_scatter(sc, d, v.normal)
        else:
            if k >= len(us):
                break
            d = diffuse_direction(v.normal, us[k])
            k += 1
        o = v.pos
    return verts


def caustic_base(sc: Section, x_light: float, angle_deg: float):
    """A caustic base path camera -> floor -> (glass or mirror chain) -> light, built backwards from
    the light point (x_light, light height) along a direction ``angle_deg`` from straight down.
    Returns the camera-first vertex list, or None if it does not reach a floor point the camera sees."""
    a = math.radians(angle_deg)
    o = np.array([x_light, 0.0, sc.light[2]])
    back = trace_base(sc, 0.0, [], start=(o, np.array([math.sin(a), 0.0, -math.cos(a)])))
    if len(back) < 3 or back[-1].surface != FLOOR or back[1].surface != SPHERE:
        return None
    floor = back[-1].pos
    t, s = cast(sc, np.asarray(sc.camera, float), unit(floor - np.asarray(sc.camera)))
    if s != FLOOR or abs(t - np.linalg.norm(floor - np.asarray(sc.camera))) > 1e-6:
        return None
    light = vertex_at(sc, o, LIGHT)
    return [Vertex(np.asarray(sc.camera, float), np.zeros(3), -1)] + back[::-1][:-1] + [light]


def base_through(sc: Section, surfaces, us, step: float = 0.25):
    """The first base path (scanning the film in ``step`` pixels) whose vertices after the camera hit
    ``surfaces`` (e.g. ``(SPHERE, SPHERE, FLOOR)``) in that order; None if there is none."""
    for film in np.arange(0.5 * step, sc.pixels, step):
        verts = trace_base(sc, film, us)
        if tuple(v.surface for v in verts[1:1 + len(surfaces)]) == tuple(surfaces):
            return verts
    return None


def caustic_example(sc: Section, delta: float, policy: str = "halfvector+reconnection+manifold"):
    """The first caustic base path (light points across the light, angles from -30 to 30 degrees)
    whose shift by ``delta`` pixels under ``policy`` succeeds; None if there is none."""
    for x_light in np.linspace(sc.light[0] + 0.05, sc.light[1] - 0.05, 7):
        for angle in np.linspace(-30.0, 30.0, 13):
            base = caustic_base(sc, x_light, angle)
            if base is not None and shift_path(sc, base, delta, policy).ok:
                return base
    return None


def film_of(sc: Section, p) -> float:
    """The film coordinate whose camera ray points at p (inverse of :func:`camera_direction`)."""
    fwd = unit(np.subtract(sc.look_at, sc.camera))
    d = unit(np.subtract(p, sc.camera))
    angle = math.atan2(fwd[0] * d[2] - fwd[2] * d[0], float(np.dot(fwd, d)))
    return (0.5 - angle / math.radians(sc.fov_deg)) * sc.pixels


@dataclass
class ShiftResult:
    """An offset path and how it was made: ``actions[i]`` shifted the segment leaving vertex i+1."""
    offset: list
    actions: list
    ok: bool
    reason: str = ""
    jacobians: list = None      # per action: the Jacobian the library returned (solid angle or area)


def _reaches(sc, a, b):
    """Visibility of b from a (the caller's ray query that reconnection and manifold leave to us)."""
    d = np.subtract(b, a)
    dist = float(np.linalg.norm(d))
    t, _ = cast(sc, a, d / dist)
    return abs(t - dist) <= VISIBLE_TOL * max(1.0, dist)


def _fail(off, actions, jacs, why):
    return ShiftResult(off, actions, False, why, jacs)


def _sphere_material(sc: Section):
    """(eta, transmissive) of the sphere for the half-vector copy (relative index int/ext)."""
    return (sc.eta, True) if sc.sphere == "glass" else (1.0, False)


def _continue(sc, off, d):
    t, s = cast(sc, off[-1].pos, d)
    if s < 0:
        off.append(Vertex(off[-1].pos + 1.5 * np.asarray(d), np.zeros(3), ESCAPED))
        return False
    off.append(vertex_at(sc, off[-1].pos + t * d, s))
    return True


def _halfvector(sc, base, off, b):
    """Copy the half vector at b (Eq. 15); returns (J_w, ok). Directions point away from the vertex."""
    eta, transmissive = _sphere_material(sc) if base[b].surface == SPHERE else (1.0, False)
    wi_b = tuple(unit(base[b - 1].pos - base[b].pos))
    wo_b = tuple(unit(base[b + 1].pos - base[b].pos))
    wi_o = tuple(unit(off[b - 1].pos - off[b].pos))
    wo, j, ok = halfvector_copy_world(tuple(base[b].normal), wi_b, wo_b, tuple(off[b].normal), wi_o, eta,
                                      transmissive)
    return j, ok and _continue(sc, off, np.array(wo))


def _replay(sc, base, off, b, k_o):
    """Same random numbers at b (STAR Sec. 3.1): an offset vertex on the sphere applies its law to its
    own incoming direction; a diffuse one takes the number of its own k_o-th diffuse bounce -- the
    base's k_o-th diffuse bounce's number, which fixes that bounce's *local* direction -- as the path
    tracer would from the same numbers (after a class mismatch k_o differs from the base's count).
    Returns (J, ok, numbers used)."""
    if off[b].surface == SPHERE:
        return 1.0, _continue(sc, off, specular_scatter(sc, unit(off[b].pos - off[b - 1].pos), off[b].normal)), 0
    if k_o < len(getattr(base, "us", ())):
        return 1.0, _continue(sc, off, diffuse_direction(off[b].normal, base.us[k_o])), 1
    # a path built without its numbers (caustic_base): each diffuse bounce's local direction is its number
    diffuse = [i for i in range(1, len(base) - 1) if base[i].vclass != L.V_SPECULAR and base[i].surface != LIGHT]
    if k_o >= len(diffuse):
        return 1.0, False, 0
    i = diffuse[k_o]
    nb, no = tuple(base[i].normal), tuple(off[b].normal)
    sb, tb = vec.coordinate_system(nb)
    so, to = vec.coordinate_system(no)
    local = vec.to_local(tuple(unit(base[i + 1].pos - base[i].pos)), sb, tb, nb)
    return 1.0, _continue(sc, off, np.array(vec.to_world(local, so, to, no))), 1


def _inverse_reconnects(sc, base, off, b):
    """Would the backward shift (base: the offset) reconnect base[b] to the offset's new vertex? Then the
    step is not reversible (gdlearn.shifts.policy, "Reversibility")."""
    y2 = off[b + 1]
    return (base[b].vclass != L.V_SPECULAR and off[b].vclass != L.V_SPECULAR and y2.surface >= 0
            and y2.vclass != L.V_SPECULAR and _reaches(sc, base[b].pos, y2.pos))


def _manifold(sc, base, off, b, end, max_iter):
    """Move the specular chain base[b+1 .. end-1] to join off[b] and base[end] (Sec. 3.4)."""
    k = end - (b + 1)
    chain = np.ascontiguousarray([v.pos for v in base[b + 1:end]])
    rows = np.array([M.sphere_row(sc.center, sc.radius)] * k)
    refract = np.full(k, sc.sphere == "glass")
    X = np.zeros((k, 3))
    j, ok, _ = M.manifold_shift(tuple(base[b].pos), tuple(off[b].pos), chain, tuple(base[end].pos),
                                tuple(base[end].normal), rows, np.full(k, sc.eta), refract, k, X, max_iter, True)
    if not ok:
        return j, False, "manifold walk failed"
    pts = [off[b].pos] + list(X) + [base[end].pos]
    if not all(_reaches(sc, pts[i], pts[i + 1]) for i in range(len(pts) - 1)):
        return j, False, "moved chain is blocked"
    off.extend(vertex_at(sc, x, SPHERE) for x in X)
    return j, True, ""


def shift_path(sc: Section, base: list, delta: float, policy: str, max_iter: int = M.MAX_ITER) -> ShiftResult:
    """Shift ``base`` (a camera-first vertex list) by ``delta`` pixels with a named policy
    (``gdlearn.shifts.policy.POLICIES``): the camera ray moves by delta, then at each vertex the
    policy's action runs. A failure (the library's flag, a class mismatch under Kettunen et al.'s
    policies, a blocked or escaping offset segment, a step the backward shift would not repeat) stops
    the walk: the offset contributes nothing (STAR Sec. 3.5). The mixed policies and ``replay`` replay
    through class mismatches; a blocked reconnection makes a mixed policy replay instead."""
    code = P.policy_code(policy)
    mixed = P.is_mixed(code)
    off = [base[0]]
    actions, jacs = [], []
    film = film_of(sc, base[1].pos) + delta
    if not _continue(sc, off, camera_direction(sc, film)):
        return _fail(off, actions, jacs, "offset camera ray leaves the scene")
    classes = np.array([v.vclass for v in base], np.int32)
    n = len(base)
    b, k_o = 1, 0
    while b < n - 1 and base[b].surface != LIGHT:
        if off[b].surface == LIGHT:
            return _fail(off, actions, jacs, "offset ends on the light early")
        a = P.choose_shift(code, base[b].vclass, off[b].vclass, classes, b, n)
        if a == P.SHIFT_FAIL:
            actions.append(P.ACTION_NAMES[a])
            return _fail(off, actions, jacs, "vertex classes differ")
        if a == P.SHIFT_RECONNECT:
            _, _, _, j_sa, ok = reconnect(tuple(base[b].pos), tuple(off[b].pos), tuple(base[b + 1].pos),
                                          tuple(base[b + 1].normal))
            if ok and _reaches(sc, off[b].pos, base[b + 1].pos):
                actions.append(P.ACTION_NAMES[a])
                jacs.append(j_sa)
                return ShiftResult(off + base[b + 1:], actions, True, "", jacs)
            if not mixed:
                actions.append(P.ACTION_NAMES[a])
                jacs.append(j_sa)
                return _fail(off + [base[b + 1]], actions, jacs, "reconnection blocked")
            a = P.mixed_action(code, base[b].vclass != L.V_SPECULAR, off[b].vclass != L.V_SPECULAR)
        actions.append(P.ACTION_NAMES[a])
        if a == P.SHIFT_MANIFOLD:
            end = P.specular_chain_end(classes, b + 1, n)
            j, ok, why = _manifold(sc, base, off, b, end, max_iter)
            jacs.append(j)
            if not ok:
                return _fail(off, actions, jacs, why)
            return ShiftResult(off + base[end:], actions, True, "", jacs)
        if a == P.SHIFT_HALFVECTOR:
            j, ok = _halfvector(sc, base, off, b)
            used = 1 if off[b].vclass != L.V_SPECULAR else 0
        else:
            j, ok, used = _replay(sc, base, off, b, k_o)
        jacs.append(j)
        k_o += used
        if not ok:
            why = "offset ray leaves the scene" if off[-1].surface == ESCAPED else f"{P.ACTION_NAMES[a]} failed"
            return _fail(off, actions, jacs, why)
        if mixed and _inverse_reconnects(sc, base, off, b):
            return _fail(off, actions, jacs, "the backward shift would reconnect")
        b += 1
    return ShiftResult(off, actions, True, "", jacs)


def failure_rates(sc: Section, policy: str, films, deltas, n_u: int, seed: int):
    """Fraction of failed shifts for each (delta, film) cell over ``n_u`` base paths (random numbers
    from ``numpy.random.default_rng(seed)``), and the count of each action that ran.

    Returns ``(rates[len(deltas), len(films)], counts, reasons)``: counts {action: (ran, failed)},
    reasons {why a shift failed: how often}."""
    rng = np.random.default_rng(seed)
    us = rng.random((len(films), n_u, 4))
    rates = np.zeros((len(deltas), len(films)))
    counts = {name: [0, 0] for name in P.ACTION_NAMES}
    reasons = {}
    for i, f in enumerate(films):
        bases = [trace_base(sc, f, us[i, k]) for k in range(n_u)]
        for r, delta in enumerate(deltas):
            for base in bases:
                if len(base) < 3:           # the camera ray escapes: nothing to shift
                    continue
                res = shift_path(sc, base, delta, policy)
                rates[r, i] += (not res.ok) / n_u
                for a in res.actions:
                    counts[a][0] += 1
                if not res.ok:
                    reasons[res.reason] = reasons.get(res.reason, 0) + 1
                    if res.actions:
                        counts[res.actions[-1]][1] += 1
    return rates, {k: tuple(v) for k, v in counts.items()}, reasons


__all__ = ["Section", "Vertex", "Path", "CEILING", "ESCAPED", "ShiftResult", "camera_direction", "cast", "trace_base", "caustic_base",
           "base_through", "caustic_example", "film_of", "shift_path", "failure_rates", "FLOOR", "WALL", "LIGHT", "SPHERE", "SURFACE_NAMES"]
