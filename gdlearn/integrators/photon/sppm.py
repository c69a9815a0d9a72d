"""Stochastic progressive photon mapping (``sppm``) and its memoryless variant (``ppm``).

``sppm`` -- Hachisuka & Jensen 2009 ("Stochastic Progressive Photon Mapping"), with the radius
and flux updates of progressive photon mapping (Hachisuka et al. 2008; PHOTONS.md Sec. 1.4): every
pass traces fresh light paths and fresh gather points; each pixel keeps a photon count N, a
radius R and the flux tau, and after a pass with M photons found inside R carrying Phi::

    N' = N + alpha M,   R'^2 = R^2 (N + alpha M) / (N + M),   tau' = (tau + Phi) R'^2 / R^2,

    L = tau / (pi R^2 N_emitted).

Stored here in the density form (PHOTONS.md Sec. 1.4; the reference code's): ``D = tau / (pi R^2)``
accumulates ``Phi / (pi R_i^2)`` with the radius of the pass, and ``L = D / N_emitted`` -- the same
number, without rescaling tau at every reduction (:func:`accumulate_density`,
:func:`reduce_radius`; ``tests/test_sppm_statistics.py`` checks the two forms agree).

``ppm`` -- Knaus & Zwicker 2011 ("Progressive Photon Mapping: A Probabilistic Approach"; PHOTONS.md
Sec. 1.5): the radius is a global schedule, ``r_i^2 = r_1^2 prod_{k=1}^{i-1} (k + alpha) / (k + 1)``,
each pass is an independent estimate at r_i, and the frame is the mean of the passes (no per-pixel
state). The name says what it is: progressive photon mapping in the probabilistic, memoryless form.

Both: surface scenes only (a scene with media is refused, naming the volumetric estimators
``vpm`` and ``bre`` of :mod:`gdlearn.integrators.photon.volumetric`); alpha 0.7 by default (the
reference code's and Gruson et al. 2018's; PHOTONS.md Appendix A); the initial radius is the pixel footprint at each pixel's gather point (PHOTONS.md Sec. 1.6), from camera paths
of a sample index no pass uses (so the radius is independent of every estimate), times
``radius_scale`` -- or ``radius`` in scene units for every pixel. Each pass emits
``photons_per_pass`` light paths in two independent halves (j < n and j >= n) gathered by two
independent gather points per pixel at the same radius: ``Frame.halves``. In ``sppm`` the halves
share N and R, driven by both halves' photon counts (PHOTONS.md Sec. 1.4: all fluxes of a gather
point share R and N), so they are independent given the radius sequence only; in ``ppm`` the
radius is a fixed schedule and the halves are fully independent. The effects plan decides
what is traced (:class:`gdlearn.photons.trace.TraceParams`) and what is gathered
(:class:`gdlearn.integrators.photon.gather.GatherParams`).
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.kernels import layout as L
from gdlearn.kernels.pathclass import CAUSTICS, DIFFUSE_INTERREFLECTION, DIRECT_LIGHTING, GLOSSY, SPECULAR
from gdlearn.photons import grid as hashgrid
from gdlearn.photons.records import BYTES_PER_VERTEX
from gdlearn.photons.trace import LightTracer, TraceParams
from gdlearn.integrators.base import PassResult
from gdlearn.integrators.combine import MeanOfPasses
from gdlearn.integrators.photon_base import PhotonPassIntegrator
from gdlearn.integrators.setup import UNBOUNDED, SceneSetup
from gdlearn.integrators.photon.gather import GatherOut, GatherParams, gather_rows

#: sample index of the camera paths that measure the initial radius (no pass reaches it)
FOOTPRINT_SAMPLE = 1 << 40
#: light-path length bound when max_depth is unbounded (Russian roulette ends paths long before)
MAX_LIGHT_VERTICES = 64
#: how sppm / ppm estimate the direct light (SurfacePhotonMapper)
DIRECT = ("photons", "nee")
#: the photon subsets by parent vertex (GatherParams.parents is the index): every photon, specular parents, the rest
PARENTS = ("any", "specular", "non-specular")
_PHOTON_CLASSES = (DIRECT_LIGHTING, DIFFUSE_INTERREFLECTION, GLOSSY, SPECULAR, CAUSTICS)


def path_bound(setup) -> int:
    """The longest path (Mitsuba's max_depth, in segments) a photon estimator traces: the scene's,
    or MAX_LIGHT_VERTICES + 1 when it is unbounded (-1)."""
    return setup.max_depth if setup.max_depth < UNBOUNDED else MAX_LIGHT_VERTICES + 1


def accumulate_density(D, phi, r2):
    """Density form of SPPM's flux: D += Phi / (pi R_i^2) (per pixel; phi may have a colour axis)."""
    inv = np.where(r2 > 0, 1.0 / (math.pi * np.where(r2 > 0, r2, 1.0)), 0.0)
    D += phi * (inv[..., None] if phi.ndim > r2.ndim else inv)
    return D


def reduce_radius(N, r2, M, alpha):
    """Progressive radius reduction (Hachisuka et al. 2008; PHOTONS.md Sec. 1.4):
    (N + alpha M, R^2 (N + alpha M) / (N + M)) per pixel."""
    tot = N + M
    ratio = np.where(tot > 0, (N + alpha * M) / np.where(tot > 0, tot, 1.0), 1.0)
    return N + alpha * M, r2 * ratio


def ppm_radius2_factor(i: int, alpha: float) -> float:
    """Knaus & Zwicker 2011's global schedule: r_{i+1}^2 / r_1^2 = prod_{k=1}^{i} (k + alpha) / (k + 1)."""
    f = 1.0
    for k in range(1, i + 1):
        f *= (k + alpha) / (k + 1)
    return f


def _refuse(setup: SceneSetup) -> None:
    if setup.media:
        raise ValueError("sppm / ppm render surfaces only and this scene has participating media; fix: use "
                         "--integrator vpm or bre (the volumetric photon estimators), or pt")
    if setup.has_null:
        raise ValueError("sppm / ppm: a 'null' BSDF only bounds media, which these estimators do not trace; "
                         "fix: remove the null shape or render with pt")
    for row in setup.sa.materials:
        if int(row[L.MAT_TYPE]) == L.ROUGHPLASTIC and row[L.MAT_ALPHA] < setup.threshold:
            raise ValueError("sppm / ppm: a roughplastic whose coating is below the roughness threshold has a "
                             "specular coating over a diffuse base inside one non-delta lobe; fix: raise its alpha "
                             f"to >= {setup.threshold} or use 'plastic'")


class SurfacePhotonMapper(PhotonPassIntegrator):
    """Shared by ``sppm`` and ``ppm``: ``make(name, scene, seed=0, photons_per_pass=100000,
    alpha=0.7, radius=None, radius_scale=1.0, direct="photons", parent="any", effects=None,
    max_depth=None, threads=None)``.

    ``photons_per_pass`` light paths are emitted per pass, half for each half-buffer; a pass always
    takes 2 camera samples per pixel (one gather point per half), whatever ``spp_per_pass`` says.
    ``direct``: "photons" (Hachisuka & Jensen 2009: every light path's photons, direct light
    included) or "nee" (direct light at the gather point by emitter sampling, the photons of the
    light paths' first vertices left out; pbrt-v3's ``SPPMIntegrator`` camera pass): the same
    image in the limit, no kernel bias in the direct light, and photons spent on indirect light
    and caustics only. ``parent="specular"`` gathers only the photons whose parent vertex is
    specular (Hua et al. 2017's Fig. 4 subset: the photons GPM's manifold branch shifts),
    ``"non-specular"`` only the others (the two images sum to the default ``"any"``)."""

    def __init__(self, scene, *, seed: int = 0, photons_per_pass: int = 100_000, alpha: float = 0.7,
                 radius=None, radius_scale: float = 1.0, direct: str = "photons", parent: str = "any", effects=None,
                 max_depth=None, threads=None, sa=None, spp_per_pass: int = 2):
        super().__init__(scene, seed=seed, spp_per_pass=2, photons_per_pass=max(2, int(photons_per_pass)))
        if not 0.0 < float(alpha) <= 1.0:
            raise ValueError(f"alpha={alpha!r} must be in (0, 1]; 0.7 is the usual choice")
        if radius is not None and not float(radius) > 0.0:
            raise ValueError(f"radius={radius!r} must be > 0 (scene units), or None for the pixel footprint")
        if parent not in PARENTS:
            raise ValueError(f"parent={parent!r}: choose 'any' (every photon), 'specular' (photons whose parent "
                             "vertex is specular) or 'non-specular' (the others)")
        if direct not in DIRECT:
            raise ValueError(f"direct={direct!r}: choose one of {', '.join(DIRECT)}")
        self.direct = direct
        self.setup = s = SceneSetup(scene, effects=effects, max_depth=max_depth, threads=threads, sa=sa)
        _refuse(s)
        self.alpha, self.radius0, self.radius_scale = float(alpha), radius, float(radius_scale)
        self.n_half = self.photons_per_pass // 2
        md = path_bound(s)
        mask = s.mask
        # surface estimators: medium vertices are never photons (and _refuse keeps media out)
        self.trace_params = TraceParams(max(0, md - 1), s.rr_depth, s.threshold,
                                        bool(mask >> CAUSTICS & 1),
                                        any(mask >> c & 1 for c in _PHOTON_CLASSES if c != CAUSTICS),
                                        want_volume=False)
        self.gather_params = GatherParams(int(min(md, UNBOUNDED)), s.threshold, mask,
                                          not all(mask >> c & 1 for c in _PHOTON_CLASSES), direct == "nee",
                                          PARENTS.index(parent))
        self.tracer = LightTracer(s.sa, self.trace_params, threads=threads)
        self.r2 = None                       # per-pixel squared radius of the next pass
        self.width, self.height = s.width, s.height
        self._last = None

    # -- radius ----------------------------------------------------------------------------------
    def _gather(self, light_paths, grids, sample0, radius):
        h, w = self.height, self.width
        out = GatherOut(np.zeros((2, h, w, 3)), np.zeros((2, h, w)), np.zeros((2, h, w, 3)), np.zeros((2, h, w)),
                        np.zeros(h, np.int64), np.zeros((2, h, w, 3)))
        with self.setup.parallel(h):
            gather_rows(self.setup.sa, light_paths, grids, self.gather_params, self.seed, sample0, radius, out)
        return out

    def initial_radius2(self) -> np.ndarray:
        """Per-pixel r_1^2: ``radius`` everywhere, else radius_scale x the pixel footprint at the
        pixel's gather point (pixels without one take the median of the others)."""
        h, w = self.height, self.width
        if self.radius0 is not None:
            return np.full((h, w), float(self.radius0) ** 2)
        lp = self.tracer.trace(self.seed, 0, 0, 1)                 # one path: the right types
        g = hashgrid.build(np.zeros((0, 3)), 1.0)
        out = self._gather(lp, (g, g), FOOTPRINT_SAMPLE, np.zeros((h, w)))
        f = out.foot
        n = (f > 0).sum(axis=0)
        foot = np.where(n > 0, f.sum(axis=0) / np.maximum(n, 1), 0.0)
        fill = np.median(foot[foot > 0]) if (foot > 0).any() else 1e-3 * float(self.setup.sa.bsphere[3])
        foot = np.where(foot > 0, foot, fill) * self.radius_scale
        return foot ** 2

    # -- the four stages ---------------------------------------------------------------------------
    def trace_photons(self, pass_index: int):
        if self.r2 is None:
            self.r2 = self.initial_radius2()
        return self.tracer.trace(self.seed, pass_index, 0, 2 * self.n_half)

    def build(self, light_paths):
        rows = light_paths.photons
        if self.direct == "nee":          # the gather point's emitter sample has the direct light
            rows = rows[light_paths.depth[rows] >= 2]
        half = light_paths.path[rows] >= self.n_half
        cell = float(np.sqrt(np.percentile(self.r2, 90)))
        grids = tuple(hashgrid.build_rows(light_paths.pos, sel, cell) for sel in (rows[~half], rows[half]))
        self._nphotons = int(rows.size)
        return light_paths, grids

    def emitted(self, photons) -> int:
        return 2 * self.n_half

    def release(self, light_paths) -> None:
        self.tracer.recycle(light_paths)

    def compile(self) -> float:
        import time
        t0 = time.perf_counter()
        lp = self.tracer.trace(self.seed, 0, 0, 4)
        g = hashgrid.build_rows(lp.pos, lp.photons, 1.0)
        s = self.setup
        h, w = s.height, s.width
        self.height, self.width = 2, 2
        try:
            self._gather(lp, (g, g), FOOTPRINT_SAMPLE, np.full((2, 2), 0.1))
        finally:
            self.height, self.width = h, w
        return time.perf_counter() - t0

    def _stats(self, out, lp):
        return {"light_paths": 2 * self.n_half, "light_vertices": len(lp), "photons_stored": self._nphotons,
                "gather_points": int((out.foot > 0).sum()), "photons_gathered": int(out.m.sum()),
                "nonfinite_samples": int(out.bad.sum())}


def _result(est, emission, stats) -> PassResult:
    """A pass's images from its two halves (axis 0): ``primal``, and ``emission`` -- the part of
    primal that the gather paths saw directly or through specular chains (added exactly, no
    photon): its noise is the camera sampling's, 2 samples a pixel a pass, and tests and figures
    that study the photon estimate mask its pixels out."""
    a, b = est[0], est[1]
    ea, eb = emission[0], emission[1]
    return PassResult(images={"primal": 0.5 * (a + b), "emission": 0.5 * (ea + eb)}, spp=2,
                      halves={"primal": (a, b), "emission": (ea, eb)}, stats=stats)


class SPPM(SurfacePhotonMapper):
    """Stochastic progressive photon mapping (module docstring): per-pixel N, R, tau."""

    name = "sppm"

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, grids = accel
        out = self._gather(lp, grids, 2 * pass_index, np.sqrt(self.r2))
        h, w = self.height, self.width
        if pass_index == 0:
            self.N = np.zeros((h, w))
            self.D = np.zeros((2, h, w, 3))
            self.E = np.zeros((2, h, w, 3))
            self.Ld = np.zeros((2, h, w, 3))
        accumulate_density(self.D, out.phi, np.broadcast_to(self.r2, (2, h, w)))
        self.E += out.le
        self.Ld += out.ld
        self._m = out.m.sum(axis=0)
        k = pass_index + 1
        em = self.E / k
        halves = self.D / (self.n_half * k) + em + self.Ld / k
        return _result(halves, em, self._stats(out, lp))

    def update_radius(self, pass_index: int) -> None:
        self.N, self.r2 = reduce_radius(self.N, self.r2, self._m, self.alpha)

    def pass_state(self) -> dict:
        return {"alpha": self.alpha, "radius": np.sqrt(self.r2), "photon_count": self.N.copy(),
                "mean_radius": float(np.sqrt(self.r2).mean())}


class PPM(SurfacePhotonMapper):
    """Memoryless progressive photon mapping (Knaus & Zwicker 2011): a global radius schedule,
    every pass an independent estimate, the frame their mean."""

    name = "ppm"
    combine = MeanOfPasses

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, grids = accel
        r2 = self.r2 * ppm_radius2_factor(pass_index, self.alpha)
        out = self._gather(lp, grids, 2 * pass_index, np.sqrt(r2))
        est = out.phi / (math.pi * r2[None, :, :, None] * self.n_half) + out.le + out.ld
        self._r_now = float(np.sqrt(r2).mean())
        return _result(est, out.le, self._stats(out, lp))

    def pass_state(self) -> dict:
        return {"alpha": self.alpha, "mean_radius": self._r_now}


def bytes_per_photon_vertex() -> int:
    """Memory of one light-path vertex record (benchmarks)."""
    return BYTES_PER_VERTEX
