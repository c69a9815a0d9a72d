"""The per-render constants of the gradient kernels, bundled: :class:`GptParams`.

numba passes a NamedTuple as a struct (one argument, no per-field cost once LLVM has inlined the
callee), so the kernels take ``cfg`` instead of six loose scalars, and a reader sees at a glance
which arguments are per-render constants and which change per vertex. Kettunen and Manzi's
gradient-domain Mitsuba bundles the same options (``GradientPathTracerConfig``).
"""
from __future__ import annotations

from typing import NamedTuple


class GptParams(NamedTuple):
    """``policy``: the shift policy code (:mod:`gdlearn.shifts.policy`); ``max_depth`` (a loop bound),
    ``rr_depth``, ``mask`` (the effects mask) and ``threshold`` (roughness below which a vertex counts
    as specular) as :class:`gdlearn.integrators.setup.SceneSetup`; ``broken``: the fault injected for
    the tests that must be able to fail (``gpt_surface.vertex.BROKEN_*``; 0 is the estimator)."""
    policy: int
    max_depth: int
    rr_depth: int
    mask: int
    threshold: float
    broken: int

    @classmethod
    def of(cls, setup, policy: int, broken: int = 0) -> "GptParams":
        """The bundle for a :class:`~gdlearn.integrators.setup.SceneSetup` (types fixed, so every render
        reuses one compiled specialisation)."""
        return cls(int(policy), int(setup.max_depth), int(setup.rr_depth), int(setup.mask), float(setup.threshold),
                   int(broken))


#: kind of the base vertex a segment leaves (:attr:`BaseVertex.kind`): the camera (the pixel shift has
#: set the offsets' first rays), a surface vertex, a medium (scattering) vertex
VB_CAMERA, VB_SURFACE, VB_MEDIUM = 0, 1, 2


class BaseVertex(NamedTuple):
    """The base path's vertex x_b that the segment x_b -> x_{b+1} being shifted leaves (Kettunen et al.
    2015; STAR, Hua et al. 2019, Sec. 3: the offset vertex x'_b is shifted against it), built where the
    base samples its direction (``gpt_surface.lockstep.gpt_sample``, ``gpt_volume.lockstep.gpt_volume_sample``).

    ``kind``: VB_CAMERA / VB_SURFACE / VB_MEDIUM; ``x``: the position x_b; ``ng`` / ``ns``: geometric and
    shading normals (zeros at a medium vertex or the camera); ``prim``: its primitive (-1: none); ``med``:
    the medium the base *arrived* in at x_b; ``mat``: its material row (a placeholder row at a medium
    vertex / the camera); ``wi`` / ``wo``: the incoming and sampled outgoing directions in the local
    shading frame; ``wo_w``: the outgoing direction in world space; ``weight``: f cos / p of the sampled
    direction; ``pdf``: its solid-angle density p_b; ``delta``: sampled from a delta lobe; ``cls_b``: the
    sampled lobe's effect class; ``cls_s``: its class for the shift decisions (:mod:`gdlearn.shifts.policy`);
    ``us``: the random numbers (u_lobe, u1, u2) the base used, replayed by the offsets."""
    kind: int
    x: tuple
    ng: tuple
    ns: tuple
    prim: int
    med: int
    mat: object
    wi: tuple
    wo: tuple
    wo_w: tuple
    weight: tuple
    pdf: float
    delta: bool
    cls_b: int
    cls_s: int
    us: tuple


class NextVertex(NamedTuple):
    """The next vertex x_{b+1} the base reached from x_b (or its escape): the vertex a reconnection joins
    x'_b to (STAR Sec. 3.3) and whose kind a shift must reproduce.

    ``hit``: a vertex was reached (False: the base escaped); ``ev``: the flight's event
    (``gpt_volume.flight.EV_*``; on surfaces EV_SURFACE or EV_ESCAPE); ``prim``: its primitive (-1 at a
    medium vertex or the escape); ``p``, ``ng``, ``ns``: position x_{b+1} and normals; ``d``: the world
    direction of the segment x_b -> x_{b+1}; ``med``: the medium the base arrived in (-1 on surfaces
    without media); ``cls``: the vertex class of x_{b+1} (``vclass_of``, V_MEDIUM, ESCAPED);
    ``delta``: x_{b+1} is a delta-only surface vertex (volume kernels; False on surfaces)."""
    hit: bool
    ev: int
    prim: int
    p: tuple
    ng: tuple
    ns: tuple
    d: tuple
    med: int
    cls: int
    delta: bool


class PathRng(NamedTuple):
    """The coordinates of the base path's random numbers (:mod:`gdlearn.kernels.rng`): number d of the path
    is ``rand(seed, key, s, d)``. ``key`` is the base pixel's (random-sequence replay, STAR Sec. 3.1: an
    offset path uses the same coordinates); ``s`` the sample index."""
    seed: int
    key: int
    s: int


class Pixel(NamedTuple):
    """The base sample's film geometry: film point (``fx``, ``fy``) inside pixel (``x``, ``y``) of a
    ``w`` x ``h`` image; the pixel shift (Eq. 3) moves (fx, fy) to the neighbours inside the image."""
    fx: float
    fy: float
    x: int
    y: int
    w: int
    h: int
