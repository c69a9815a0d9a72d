"""Effect classes of light paths, computed incrementally while a camera path is traced.

The effects plan (:mod:`gdlearn.scene.effects`, ARCHITECTURE.md "Effects, not switches") lets a
caller render only some light transport, e.g. caustics alone. The path tracer pushes the class of
every interior vertex (``layout.V_DIFFUSE``, ``V_GLOSSY``, ``V_SPECULAR``, ``V_MEDIUM``) onto one
int64 *state* as it extends the camera path, asks :func:`pc_class` for the class of the path that
ends at a light right after the vertices pushed so far (next-event estimation from the last vertex,
or an emitter hit by the next ray: both give the same class), adds the contribution only if that
class is requested, and stops the path as soon as :func:`pc_reachable` says no extension can produce
a requested class.

Classes, in Heckbert's regular-expression notation read from the light L to the eye E (a path's
*interior* vertices are its scattering vertices; null interfaces are not vertices):

=======================  ========================================================================
EMISSION                 L E: no interior vertex (emitters seen directly)
DIRECT_LIGHTING          L X E, X a surface vertex of any kind
DIFFUSE_INTERREFLECTION  >= 2 interior vertices, all diffuse surface vertices (L D D+ E)
GLOSSY                   >= 2 surface vertices, some glossy, none specular, no medium vertex
SPECULAR                 >= 2 surface vertices, some specular, no medium, not a caustic
CAUSTICS                 L S+ (D|G) ... E: from the light, specular vertices then a non-specular
                         surface vertex, anything after (the L S+ D E caustics of Heckbert 1990)
SINGLE_SCATTERING        L M E: exactly one interior vertex, a medium scattering event
MULTIPLE_SCATTERING      >= 2 interior vertices, at least one in a medium, not a caustic
VOLUME_CAUSTICS          L S+ M ... E: specular vertices from the light, then a medium vertex
=======================  ========================================================================

Every path with interior vertices in {D, G, S, M} falls in exactly one class. A vertex on a
material with lobes of two classes (a plastic: delta or microfacet coating over a diffuse base) is
of the class of the lobe that produced the next direction. For BSDF samples that is the sampled lobe;
a next-event term, which no lobe produced, is split by each lobe's posterior probability of having
produced its direction (:func:`!gdlearn.kernels.bsdf.dispatch.nee_class_share`), so the two MIS strategies
estimate the same per-class image and the classes still sum to the full one. Since the light end
is reached last, the state tracks: the number of interior vertices, which vertex classes occurred,
the length of the current trailing run of specular vertices and the class of the last non-specular
vertex (the vertex just before that run). Packed in one int64 (counts saturate at 0xFFFF)::

    bits  0-15  n, interior vertices          bits 32-35  flags: diffuse, glossy, specular, medium
    bits 16-31  r, trailing specular run      bits 36-38  class of the last non-specular vertex
                                                          (NO_VERTEX = 4 if none)
                                              bits 39-40  the camera's end (below)

The camera's end. The classes above are read from the light. Gruson et al. 2018 study the light
transport *ending in the medium* (their experiments' setting, PHOTONS.md E15): paths whose first
non-specular vertex seen from the camera is a medium scattering event (E S* M ... L). The state
also records that vertex's kind (``EYE_NONE`` while the camera prefix is a specular chain,
``EYE_SURFACE`` for a diffuse or glossy vertex, ``EYE_MEDIUM``), and the mask bit
``MEDIA_TRANSPORT`` (above the class bits) keeps only paths with ``EYE_MEDIUM``: the quantity the
volumetric photon estimators compute with ``transport="media"``, here for any integrator that
pushes the camera path's vertices in order (the path tracer gives its unbiased reference).
``SURFACE_TRANSPORT`` keeps the complement, so the two images add up to the full one.
"""
from __future__ import annotations


from gdlearn.kernels.layout import V_DIFFUSE, V_GLOSSY, V_MEDIUM, V_SPECULAR
from gdlearn.kernels.jit import block

EMISSION = 0
DIRECT_LIGHTING = 1
DIFFUSE_INTERREFLECTION = 2
GLOSSY = 3
SPECULAR = 4
CAUSTICS = 5
SINGLE_SCATTERING = 6
MULTIPLE_SCATTERING = 7
VOLUME_CAUSTICS = 8
N_CLASSES = 9

#: effect names used by the CLI, scene files and the effects plan, indexed by class
CLASS_NAMES = ("emission", "direct-lighting", "diffuse-interreflection", "glossy", "specular",
               "caustics", "single-scattering", "multiple-scattering", "volume-caustics")
ALL_MASK = (1 << N_CLASSES) - 1
#: mask bits, not classes: keep only paths whose first non-specular camera vertex is a medium
#: scattering event (light transport ending in the medium), or only the others (its complement:
#: a surface vertex, or none -- emission seen directly or through a specular chain)
MEDIA_TRANSPORT = 1 << 16
SURFACE_TRANSPORT = 1 << 17
#: the camera's end of a path (state bits 39-40): no non-specular vertex yet, a surface, a medium
EYE_NONE, EYE_SURFACE, EYE_MEDIUM = 0, 1, 2

NO_VERTEX = 4
_SAT = 0xFFFF
_F_SHIFT = 32
_B_SHIFT = 36
_E_SHIFT = 39
# classes that need two or more interior vertices: no bound on the path length helps them
_LONG_MASK = ((1 << DIFFUSE_INTERREFLECTION) | (1 << GLOSSY) | (1 << SPECULAR) | (1 << CAUSTICS) |
              (1 << MULTIPLE_SCATTERING) | (1 << VOLUME_CAUSTICS))


@block
def pc_init():
    """The state of a camera path with no interior vertex yet."""
    return (NO_VERTEX << _B_SHIFT) + 0  # int64


@block
def _n(state):
    return state & _SAT


@block
def _r(state):
    return (state >> 16) & _SAT


@block
def _flags(state):
    return (state >> _F_SHIFT) & 0xF


@block
def _before(state):
    return (state >> _B_SHIFT) & 0x7


@block
def pc_eye(state):
    """The kind of the first non-specular vertex from the camera: EYE_NONE, EYE_SURFACE or EYE_MEDIUM."""
    return (state >> _E_SHIFT) & 0x3


@block
def pc_push(state, vclass):
    """Append one interior vertex of class ``vclass`` (a ``layout.V_*``) at the light end."""
    n = _n(state)
    r = _r(state)
    flags = _flags(state) | (1 << vclass)
    before = _before(state)
    eye = pc_eye(state)
    if n < _SAT:
        n += 1
    if vclass == V_SPECULAR:
        if r < _SAT:
            r += 1
    else:
        r = 0
        before = vclass
        if eye == EYE_NONE:
            eye = EYE_MEDIUM if vclass == V_MEDIUM else EYE_SURFACE
    return n | (r << 16) | (flags << _F_SHIFT) | (before << _B_SHIFT) | (eye << _E_SHIFT)


@block
def pc_wanted(state, mask):
    """Does ``mask`` keep the path made of the pushed vertices followed by a light? Its class bit,
    and with ``MEDIA_TRANSPORT`` (``SURFACE_TRANSPORT``) a first non-specular camera vertex that is
    (is not) a medium scattering event."""
    if (mask >> pc_class(state)) & 1 == 0:
        return False
    if (mask & MEDIA_TRANSPORT) != 0:
        return pc_eye(state) == EYE_MEDIUM
    if (mask & SURFACE_TRANSPORT) != 0:
        return pc_eye(state) != EYE_MEDIUM
    return True


@block
def pc_class(state):
    """Class of the path made of the pushed vertices followed by a light (Heckbert notation above)."""
    n = _n(state)
    if n == 0:
        return EMISSION
    flags = _flags(state)
    has_medium = (flags >> V_MEDIUM) & 1
    if n == 1:
        return SINGLE_SCATTERING if has_medium else DIRECT_LIGHTING
    if _r(state) > 0:                       # L S+ then ...
        b = _before(state)
        if b == V_DIFFUSE or b == V_GLOSSY:
            return CAUSTICS
        if b == V_MEDIUM:
            return VOLUME_CAUSTICS
    if has_medium:
        return MULTIPLE_SCATTERING
    if (flags >> V_SPECULAR) & 1:
        return SPECULAR
    if (flags >> V_GLOSSY) & 1:
        return GLOSSY
    return DIFFUSE_INTERREFLECTION


@block
def pc_reachable(state, mask):
    """Can this prefix, as it is or extended by more vertices of any class, give a class in ``mask``?

    With k >= 1 more vertices (two always suffice): caustics (push D, S), volume caustics (M, S) and
    multiple scattering (M, M) are always reachable; specular needs no medium vertex so far (push S
    then D, so the path does not end in a caustic); glossy needs no specular and no medium vertex;
    diffuse interreflection needs only diffuse vertices so far; direct lighting and single
    scattering need an empty prefix. The camera's end: with ``MEDIA_TRANSPORT`` a prefix whose
    first non-specular vertex is a surface gives nothing, and a specular-only prefix can still
    reach only the classes holding a medium vertex (the next non-specular vertex must be one); with
    ``SURFACE_TRANSPORT`` the reverse, and single scattering (``M`` alone) is out.
    """
    eye = pc_eye(state)
    media = (mask & MEDIA_TRANSPORT) != 0
    surfaces = (mask & SURFACE_TRANSPORT) != 0
    if (media and eye == EYE_SURFACE) or (surfaces and eye == EYE_MEDIUM):
        return False
    if pc_wanted(state, mask):
        return True
    flags = _flags(state)
    ext = (1 << CAUSTICS) | (1 << VOLUME_CAUSTICS) | (1 << MULTIPLE_SCATTERING)
    if _n(state) == 0:
        ext |= (1 << DIRECT_LIGHTING) | (1 << SINGLE_SCATTERING)
    if (flags >> V_MEDIUM) & 1 == 0:
        ext |= 1 << SPECULAR
        if (flags >> V_SPECULAR) & 1 == 0:
            ext |= 1 << GLOSSY
            if (flags >> V_GLOSSY) & 1 == 0:
                ext |= 1 << DIFFUSE_INTERREFLECTION
    if eye == EYE_NONE:
        if media:
            ext &= (1 << CAUSTICS) | (1 << VOLUME_CAUSTICS) | (1 << MULTIPLE_SCATTERING) | (1 << SINGLE_SCATTERING)
        elif surfaces:
            ext &= ~(1 << SINGLE_SCATTERING)
    return (ext & mask) != 0


@block
def pc_max_interior(mask):
    """Most interior vertices a path of a class in ``mask`` can have; -1 if unbounded."""
    if mask & _LONG_MASK:
        return -1
    if mask & ((1 << DIRECT_LIGHTING) | (1 << SINGLE_SCATTERING)):
        return 1
    return 0
