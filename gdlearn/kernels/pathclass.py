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

NO_VERTEX = 4
_SAT = 0xFFFF
_F_SHIFT = 32
_B_SHIFT = 36
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
def pc_push(state, vclass):
    """Append one interior vertex of class ``vclass`` (a ``layout.V_*``) at the light end."""
    n = _n(state)
    r = _r(state)
    flags = _flags(state) | (1 << vclass)
    before = _before(state)
    if n < _SAT:
        n += 1
    if vclass == V_SPECULAR:
        if r < _SAT:
            r += 1
    else:
        r = 0
        before = vclass
    return n | (r << 16) | (flags << _F_SHIFT) | (before << _B_SHIFT)


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
    scattering need an empty prefix.
    """
    if (mask >> pc_class(state)) & 1:
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
    return (ext & mask) != 0


@block
def pc_max_interior(mask):
    """Most interior vertices a path of a class in ``mask`` can have; -1 if unbounded."""
    if mask & _LONG_MASK:
        return -1
    if mask & ((1 << DIRECT_LIGHTING) | (1 << SINGLE_SCATTERING)):
        return 1
    return 0
