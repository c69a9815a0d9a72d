"""The camera side of the volumetric photon estimators: a gather path whose medium segments are beams.

In a participating medium the camera path does not sample collisions. It uses *long beams*
(Gruson et al. 2018, Sec. 4.1 and 6; PHOTONS.md Sec. 1.7): every segment the path travels inside
a medium is a **camera beam** -- origin, unit direction, length s (infinite if the ray leaves the
scene), the medium, and the camera weight at its start -- and the path goes on to the next surface
with the segment's transmittance T(s) as its weight. The medium radiance is then estimated along
each beam as a whole by the volumetric estimator (VPM's distance samples, the beam radiance
estimate's discs or balls; :mod:`gdlearn.integrators.photon.volume_estimates`), which is the
volume rendering equation (Jarosz et al. 2008, Eq. 1)::

    L(x, w) = T(s) L(x_s) + int_0^s T(t) sigma_s L_i(x_t) dt

read from the camera: the integral is the beams' job, the first term is the path's weight at the
surface it goes on to. Surfaces are handled as in surface photon mapping
(:mod:`gdlearn.integrators.photon.gather`): specular vertices continue the chain, the first
non-specular one is the gather point, emission seen directly or through the chain is added
exactly. ``null`` interfaces (a medium's boundary) change the medium and are not vertices.

Path length (Mitsuba's max_depth counts segments): a beam that starts after m surface vertices is
merged with a volume photon of light depth k into a path of m + 1 + k segments; beams after which
no photon fits (m + 2 > max_depth) are not recorded.

A beam is one row of a small scratch array (``BEAM_*`` columns) the row driver owns, with the
effects-plan state of the camera prefix (the beam point's V_MEDIUM pushed) and m beside it.
"""
from __future__ import annotations

import math

from gdlearn.kernels.accel.bvh import closest_hit_inline
from gdlearn.kernels.bsdf.dispatch import bsdf_is_null
from gdlearn.kernels.geometry import INFO_EMITTER, INFO_MAT, offset_origin, surface
from gdlearn.kernels.layout import V_MEDIUM
from gdlearn.kernels.lights import eval_emitter
from gdlearn.kernels.media.boundary import next_medium
from gdlearn.kernels.media.medium import medium_params, transmittance
from gdlearn.kernels.pathclass import pc_init, pc_push
from gdlearn.kernels.vec import coordinate_system, to_local, to_world
from gdlearn.kernels.jit import block
from gdlearn.integrators.photon.gather import GATHER, STOP, _leave, _plus, _wanted

#: columns of a beam row: origin (3), direction (3), length, medium row, camera weight (3)
BEAM_O, BEAM_D, BEAM_S, BEAM_MED, BEAM_W = 0, 3, 6, 7, 8
BEAM_COLS = 11
#: beams a camera path records at most (one per medium segment; a specular chain through glass in
#: fog has a few); later segments are still traced for the surface, their medium is left out
MAX_BEAMS = 16
#: segments a camera path may take (null crossings are not bounces: max_depth does not bound them)
MAX_SEGMENTS = 256


@block
def beam_path(sa, prm, h, o, d, stack, beams, bstate):
    """Trace a camera path with long beams from (o, d); ``beams`` (MAX_BEAMS x BEAM_COLS) and
    ``bstate`` (MAX_BEAMS x 2: effects state with the beam point pushed, surface vertices before
    the beam) receive the camera beams. Returns the gather point as
    :func:`!gdlearn.integrators.photon.gather.gather_path` does -- (ok, p, ng, frame, wi, mat row,
    weight incl. transmittance, state, m, travelled distance, emission) -- and the beam count."""
    le = (0.0, 0.0, 0.0)
    beta = (1.0, 1.0, 1.0)
    state = pc_init()
    zero = (0.0, 0.0, 0.0)
    travelled = 0.0
    medium = sa.camera_medium
    m = 0
    nb = 0
    for _ in range(MAX_SEGMENTS):
        t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf,
                                           stack)
        if medium >= 0:
            if m + 2 <= prm.max_depth and nb < MAX_BEAMS:
                _record(beams, bstate, nb, o, d, t, medium, beta, pc_push(state, V_MEDIUM), m)
                nb += 1
            tr = transmittance(medium_params(sa.media[medium])[0], t)
            beta = (beta[0] * tr[0], beta[1] * tr[1], beta[2] * tr[2])
        if prim < 0:
            if sa.env >= 0 and _wanted(prm.mask, state):
                le = _plus(le, beta, eval_emitter(sa.emitters, sa.env, d, d))
            break
        travelled += t
        p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
        em = sa.prim_info[prim, INFO_EMITTER]
        if em >= 0 and _wanted(prm.mask, state):
            le = _plus(le, beta, eval_emitter(sa.emitters, em, ns, d))
        mid = sa.prim_info[prim, INFO_MAT]
        if bsdf_is_null(sa.materials[mid]):       # an index-matched interface: not a vertex
            medium = next_medium(sa.prim_info, prim, medium, d, ng)
            o = offset_origin(p, ng, d)
            continue
        if m + 2 > prm.max_depth:          # no room for a photon's light segment after this vertex
            break
        s, tt = coordinate_system(ns)
        wi = to_local((-d[0], -d[1], -d[2]), s, tt, ns)
        what, wo, beta, state = _leave(sa.materials[mid], prm, h, 2 + 3 * m, wi, state, beta)
        if what == GATHER:
            return True, p, ng, (ns, s, tt), wi, mid, beta, state, m, travelled, le, nb
        if what == STOP:
            break
        d = to_world(wo, s, tt, ns)
        o = offset_origin(p, ng, d)
        medium = next_medium(sa.prim_info, prim, medium, d, ng)
        m += 1
    return False, zero, zero, (zero, zero, zero), zero, -1, beta, state, m, travelled, le, nb


@block
def _record(beams, bstate, k, o, d, t, medium, beta, state, m):
    for c in range(3):
        beams[k, BEAM_O + c] = o[c]
        beams[k, BEAM_D + c] = d[c]
        beams[k, BEAM_W + c] = beta[c]
    beams[k, BEAM_S] = t
    beams[k, BEAM_MED] = medium
    bstate[k, 0] = state
    bstate[k, 1] = m


def beam_tuple(beams, k):
    """(o, d, s, medium, weight) of beam row k, for Python callers (tests)."""
    b = beams[k]
    return (tuple(b[BEAM_O:BEAM_O + 3]), tuple(b[BEAM_D:BEAM_D + 3]), float(b[BEAM_S]), int(b[BEAM_MED]),
            tuple(b[BEAM_W:BEAM_W + 3]))
