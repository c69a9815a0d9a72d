"""Volumetric photon mapping (``vpm``) and the beam radiance estimate (``bre``): full images with media.

Both trace light paths with volume photons at every medium vertex (:mod:`gdlearn.photons.trace`,
``want_volume``), and camera paths with long beams (:mod:`gdlearn.integrators.photon.camera_beams`).
A pixel's value is, per independent half (two light-path sets, two camera samples), the sum of

* the emission seen through the specular chain (exact),
* the surface photon estimate at the first non-specular vertex, weighted by the transmittance
  on the way (as :mod:`gdlearn.integrators.photon.sppm`),
* the medium radiance along every camera beam (:mod:`gdlearn.integrators.photon.volume_estimates`),

so the image converges to Mitsuba 3's ``volpath`` on the same file. ``transport="media"`` keeps
only the last term: light transport ending in the medium, the setting of Gruson et al. 2018's
experiments (PHOTONS.md E15).

* ``vpm`` -- the point-point estimate progressively (Gruson et al. 2018, Sec. 6.1; PHOTONS.md
  Sec. 1.4 and 3.7): K stratified distance samples per camera path, a uniform ball, and per-pixel
  SPPM statistics with the cube root, ``N' = N + alpha M``, ``R'^3 = R^3 (N + alpha M) / (N + M)``,
  M the photons found by all the pixel's samples of the pass, in the density form
  ``D += Phi / (4/3 pi R^3)``. The surface part keeps SPPM's own per-pixel statistics (2D).
* ``bre`` -- the beam radiance estimate (Jarosz et al. 2008), 2D (biweight) or 3D (uniform ball,
  chord sampling), each pass an independent estimate at the pass's radii and the frame their mean
  (Knaus & Zwicker 2011): per-photon radii r_i = f_i r_i^(0), with r^(0) fixed, k-NN
  (``knn``: the distance to the n-th nearest photon) or variable kernels (``variable``: Jarosz
  et al. 2008, Sec. 4, d_{i,m} (n/m)^(1/3), m = sqrt(n); :mod:`gdlearn.photons.radii`), and the
  global schedule f_i^k = prod_{j=1}^{i-1} (j + alpha) / (j + 1) with k the kernel's dimension
  (Knaus & Zwicker's recurrence, not the reference code's off-by-one variant: PHOTONS.md Sec. 1.5,
  E13). The surface part takes the same schedule with k = 2 (``ppm``).

Radii. The surface radius starts at the pixel footprint (``radius_scale`` x it, or ``radius``).
The volume radius starts at ``volume_radius`` (scene units), or else at ``volume_radius_scale`` x
the median distance from a volume photon to its ``neighbors``-th nearest, measured on pilot light
paths of a pass index no pass uses (so the radius is independent of every estimate). PHOTONS.md
Sec. 1.6 quotes the paper's 0.10-0.15 % of the medium's bounding sphere; a density-based default
suits any scene scale and photon budget. Radii are clamped below at 1e-9 of the scene's bounding
sphere, so a late pass never divides by a zero volume.

No ``cameraSphere`` skip of photons near the camera (a hidden bias of the reference code,
PHOTONS.md Sec. 1.1): every photon counts. Scenes without media are refused (use ``sppm``).
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.kernels.pathclass import (CAUSTICS, DIFFUSE_INTERREFLECTION, DIRECT_LIGHTING, GLOSSY, MULTIPLE_SCATTERING,
                                      SINGLE_SCATTERING, SPECULAR, VOLUME_CAUSTICS)
from gdlearn.photons import bbh as bbh_mod
from gdlearn.photons import grid as hashgrid
from gdlearn.photons import radii as radii_mod
from gdlearn.photons.records import K_MEDIUM, K_SURFACE
from gdlearn.photons.trace import LightTracer, TraceParams
from gdlearn.integrators.base import PassResult
from gdlearn.integrators.combine import MeanOfPasses
from gdlearn.integrators.photon_base import PhotonPassIntegrator
from gdlearn.integrators.photon.gather import GatherParams
from gdlearn.integrators.photon.sppm import (FOOTPRINT_SAMPLE, accumulate_density, path_bound,
                                             ppm_radius2_factor, reduce_radius)
from gdlearn.integrators.photon import volume_gather as vg
from gdlearn.integrators.setup import UNBOUNDED, SceneSetup

#: the pass index of the pilot light paths that measure the default volume radius
PILOT_PASS = 1 << 40
TRANSPORT = ("all", "media")
_CLASSES = (DIRECT_LIGHTING, DIFFUSE_INTERREFLECTION, GLOSSY, SPECULAR, CAUSTICS)
_MEDIUM_CLASSES = (SINGLE_SCATTERING, MULTIPLE_SCATTERING, VOLUME_CAUSTICS)
#: the smallest radius, relative to the scene's bounding sphere
R_MIN = 1e-9


def reduce_radius3(N, r, M, alpha):
    """Per-pixel 3D radius reduction (PHOTONS.md Sec. 1.4): N + alpha M, R (ratio)^(1/3)."""
    tot = N + M
    ratio = np.where(tot > 0, (N + alpha * M) / np.where(tot > 0, tot, 1.0), 1.0)
    return N + alpha * M, r * np.cbrt(ratio)


class VolumetricPhotonMapper(PhotonPassIntegrator):
    """Shared by ``vpm`` and ``bre``: ``make(name, scene, seed=0, photons_per_pass=100000, alpha=0.7,
    radius=None, radius_scale=1.0, volume_radius=None, volume_radius_scale=1.0, neighbors=32,
    transport="all", effects=None, max_depth=None, threads=None)`` (module docstring)."""

    method = vg.VPM

    def __init__(self, scene, *, seed: int = 0, photons_per_pass: int = 100_000, alpha: float = 0.7,
                 radius=None, radius_scale: float = 1.0, volume_radius=None, volume_radius_scale: float = 1.0,
                 neighbors: int = 32, transport: str = "all", samples: int = 8, effects=None, max_depth=None,
                 threads=None, sa=None, spp_per_pass: int = 2):
        super().__init__(scene, seed=seed, spp_per_pass=2, photons_per_pass=max(2, int(photons_per_pass)))
        _check(alpha, radius, volume_radius, neighbors, transport, samples)
        self.setup = s = SceneSetup(scene, effects=effects, max_depth=max_depth, threads=threads, sa=sa)
        if not s.media:
            raise ValueError(f"{self.name}: this scene has no participating medium (or the effects plan leaves "
                             "it out); fix: render surfaces with --integrator sppm (or ppm, pt)")
        self.alpha, self.radius0, self.radius_scale = float(alpha), radius, float(radius_scale)
        self.volume_radius0, self.volume_radius_scale = volume_radius, float(volume_radius_scale)
        self.neighbors, self.transport = int(neighbors), transport
        self.n_half = self.photons_per_pass // 2
        md = path_bound(s)
        mask = s.mask
        surfaces = transport == "all"
        # Surface photons after a medium vertex (L M D E, L S M D E) belong to the medium classes, so
        # these ask for surface photons of both kinds; the merge-time class filter keeps what the plan wants.
        media_classes = any(mask >> c & 1 for c in _MEDIUM_CLASSES)
        self.trace_params = TraceParams(max(0, md - 1), s.rr_depth, s.threshold,
                                        bool(mask >> CAUSTICS & 1) or media_classes,
                                        any(mask >> c & 1 for c in _CLASSES if c != CAUSTICS) or media_classes,
                                        want_volume=True)
        self.gather_params = GatherParams(int(min(md, UNBOUNDED)), s.threshold, mask,
                                          not all(mask >> c & 1 for c in _CLASSES + _MEDIUM_CLASSES), False)
        self.vparams = vg.VolumeParams(self.method, int(samples), surfaces, self._knn())
        self.tracer = LightTracer(s.sa, self.trace_params, threads=threads)
        self.width, self.height = s.width, s.height
        self.r_min = R_MIN * float(s.sa.bsphere[3])
        self.r2 = None            # surface: per-pixel squared radius of the next pass
        self.rv0 = None           # volume: the initial radius (scene units)

    # -- radii --------------------------------------------------------------------------------------
    def _knn(self) -> int:
        """k of a k-NN radius at each VPM distance sample (0: the pixel's progressive radius)."""
        return 0

    def _run(self, lp, sgrids, vgrids, bbhs, radius, sample0, r_surf, r_vol) -> vg.VolumeOut:
        out = vg.new_out(self.height, self.width)
        with self.setup.parallel(self.height):
            vg.gather_rows(self.setup.sa, lp, sgrids, vgrids, bbhs, radius, self.gather_params, self.vparams,
                           self.seed, sample0, r_surf, r_vol, out)
        return out

    def _empty(self, lp):
        g = hashgrid.build(np.zeros((0, 3)), 1.0)
        b = bbh_mod.build(np.zeros((0, 3)), np.zeros(0))
        return (g, g), (g, g), (b, b), np.zeros(max(1, len(lp)))

    def _footprint_pass(self):
        """The camera pass at a sample index no pass uses, without photons: footprints and probes."""
        if getattr(self, "_fp", None) is None:
            lp = self.tracer.trace(self.seed, 0, 0, 1)
            sg, vgr, bb, rad = self._empty(lp)
            z = np.zeros((self.height, self.width))
            self._fp = self._run(lp, sg, vgr, bb, rad, FOOTPRINT_SAMPLE, z, z)
        return self._fp

    def initial_radius2(self) -> np.ndarray:
        """Per-pixel surface r_1^2 (as sppm: ``radius``, or radius_scale x the pixel footprint)."""
        h, w = self.height, self.width
        if self.radius0 is not None:
            return np.full((h, w), float(self.radius0) ** 2)
        f = self._footprint_pass().foot
        n = (f > 0).sum(axis=0)
        foot = np.where(n > 0, f.sum(axis=0) / np.maximum(n, 1), 0.0)
        fill = np.median(foot[foot > 0]) if (foot > 0).any() else 1e-3 * float(self.setup.sa.bsphere[3])
        return (np.where(foot > 0, foot, fill) * self.radius_scale) ** 2

    def initial_volume_radius(self) -> float:
        """The volume radius of the first pass: ``volume_radius``, or volume_radius_scale x the
        median, over points the camera beams see (one per camera sample, at a free-flight distance),
        of the distance to the ``neighbors``-th nearest volume photon of one half of pilot light paths
        (a pass index no pass uses): the kernel holds about ``neighbors`` photons where the camera
        looks, whatever the scene's scale or the photon budget."""
        if self.volume_radius0 is not None:
            return float(self.volume_radius0)
        fallback = 1e-2 * float(self.setup.sa.bsphere[3])
        probes = self._footprint_pass().probe.reshape(-1, 3)
        probes = probes[np.isfinite(probes).all(axis=1)]
        lp = self.tracer.trace(self.seed, PILOT_PASS, 0, self.n_half)
        pos = lp.pos[self._volume_rows(lp)].copy()
        self.tracer.recycle(lp)
        if pos.shape[0] <= self.neighbors or probes.shape[0] == 0:
            return fallback * self.volume_radius_scale
        from scipy.spatial import cKDTree
        d, _ = cKDTree(pos).query(probes, k=self.neighbors, workers=self.setup.threads or -1)
        return float(np.median(d[:, -1])) * self.volume_radius_scale

    @staticmethod
    def _volume_rows(lp):
        rows = lp.photons
        return rows[lp.kind[rows] == K_MEDIUM]

    # -- the stages ---------------------------------------------------------------------------------
    def trace_photons(self, pass_index: int):
        if self.r2 is None:
            self.r2 = self.initial_radius2()
            self.rv0 = max(self.initial_volume_radius(), self.r_min)
        return self.tracer.trace(self.seed, pass_index, 0, 2 * self.n_half)

    def _halves(self, lp, rows):
        half = lp.path[rows] >= self.n_half
        return rows[~half], rows[half]

    def _surface_grids(self, lp):
        if not self.vparams.surfaces:
            g = hashgrid.build(np.zeros((0, 3)), 1.0)
            return (g, g)
        rows = lp.photons
        rows = rows[lp.kind[rows] == K_SURFACE]
        cell = float(np.sqrt(np.percentile(self.r2, 90)))
        return tuple(hashgrid.build_rows(lp.pos, sel, cell) for sel in self._halves(lp, rows))

    def emitted(self, photons) -> int:
        return 2 * self.n_half

    def release(self, photons) -> None:
        self.tracer.recycle(photons)

    def compile(self) -> float:
        import time
        t0 = time.perf_counter()
        lp = self.tracer.trace(self.seed, 0, 0, 4)
        sg, vgr, bb, rad = self._empty(lp)
        h, w = self.height, self.width
        self.height, self.width = 2, 2
        try:
            self._run(lp, sg, vgr, bb, rad, FOOTPRINT_SAMPLE, np.full((2, 2), 0.1), np.full((2, 2), 0.1))
        finally:
            self.height, self.width = h, w
        return time.perf_counter() - t0

    def _stats(self, out, lp, nvol):
        return {"light_paths": 2 * self.n_half, "light_vertices": len(lp), "volume_photons": int(nvol),
                "photons_gathered": int(out.m.sum()), "volume_photons_gathered": int(out.mv.sum()),
                "nonfinite_samples": int(out.bad.sum())}


def _check(alpha, radius, volume_radius, neighbors, transport, samples):
    if not 0.0 < float(alpha) <= 1.0:
        raise ValueError(f"alpha={alpha!r} must be in (0, 1]; 0.7 is the usual choice")
    for name, r in (("radius", radius), ("volume_radius", volume_radius)):
        if r is not None and not float(r) > 0.0:
            raise ValueError(f"{name}={r!r} must be > 0 (scene units), or None for the default")
    if int(neighbors) < 1:
        raise ValueError(f"neighbors={neighbors!r}: the radius needs at least 1 neighbour (32 is the default)")
    if transport not in TRANSPORT:
        raise ValueError(f"transport={transport!r}: choose one of {', '.join(TRANSPORT)}")
    if int(samples) < 1:
        raise ValueError(f"samples={samples!r}: VPM needs at least one distance sample per camera path")


def _result(est, emission, stats) -> PassResult:
    a, b = est[0], est[1]
    return PassResult(images={"primal": 0.5 * (a + b), "emission": 0.5 * (emission[0] + emission[1])}, spp=2,
                      halves={"primal": (a, b), "emission": (emission[0], emission[1])}, stats=stats)


class VPM(VolumetricPhotonMapper):
    """Progressive volumetric photon mapping (module docstring): per-pixel statistics, surface and
    volume. ``radii="knn"``: Jarosz et al. 2008's conventional estimate instead, the radius at each
    distance sample the distance to its ``neighbors``-th nearest photon (at most KNN_CAP x the
    initial volume radius), the frame the mean of the passes; biased at every photon count."""

    name = "vpm"
    method = vg.VPM
    RADII = ("fixed", "knn")
    #: how far the k-NN search may reach, in initial volume radii (a sample with fewer photons
    #: within that distance counts those it found in a ball of this radius)
    KNN_CAP = 4.0

    def __init__(self, scene, *, radii: str = "fixed", **options):
        if radii not in self.RADII:
            raise ValueError(f"radii={radii!r}: vpm takes fixed (progressive per-pixel radii) or knn")
        self.radii = radii
        super().__init__(scene, **options)

    def _knn(self) -> int:
        return self.neighbors if self.radii == "knn" else 0

    def build(self, lp):
        vsel = self._halves(lp, self._volume_rows(lp))
        rv = getattr(self, "rv", None)
        cell = float(np.percentile(rv, 90)) if rv is not None and not self._knn() else self.rv0
        self._nvol = sum(s.size for s in vsel)
        b = bbh_mod.build(np.zeros((0, 3)), np.zeros(0))
        vgrids = tuple(hashgrid.build_rows(lp.pos, s, max(cell, self.r_min)) for s in vsel)
        return lp, self._surface_grids(lp), vgrids, (b, b)

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, sg, vgr, bb = accel
        h, w = self.height, self.width
        if pass_index == 0:
            self.N, self.Nv = np.zeros((h, w)), np.zeros((h, w))
            self.rv = np.full((h, w), self.rv0 * (self.KNN_CAP if self._knn() else 1.0))
            self.D, self.Dv, self.E = np.zeros((2, h, w, 3)), np.zeros((2, h, w, 3)), np.zeros((2, h, w, 3))
        out = self._run(lp, sg, vgr, bb, np.zeros(1), 2 * pass_index, np.sqrt(self.r2), self.rv)
        accumulate_density(self.D, out.phi, np.broadcast_to(self.r2, (2, h, w)))
        vol = np.ones_like(self.rv) if self._knn() else 4.0 / 3.0 * math.pi * self.rv ** 3   # k-NN: in phiv
        self.Dv += out.phiv / vol[None, :, :, None]
        self.E += out.le
        self._m, self._mv = out.m.sum(axis=0), out.mv.sum(axis=0)
        k = pass_index + 1
        em = self.E / k
        est = (self.D + self.Dv) / (self.n_half * k) + em
        return _result(est, em, self._stats(out, lp, self._nvol))

    def update_radius(self, pass_index: int) -> None:
        self.N, self.r2 = reduce_radius(self.N, self.r2, self._m, self.alpha)
        if not self._knn():
            self.Nv, rv = reduce_radius3(self.Nv, self.rv, self._mv, self.alpha)
            self.rv = np.maximum(rv, self.r_min)

    def pass_state(self) -> dict:
        return {"alpha": self.alpha, "mean_radius": float(np.sqrt(self.r2).mean()),
                "mean_volume_radius": float(self.rv.mean()), "volume_radius": self.rv.copy()}


class BRE(VolumetricPhotonMapper):
    """The beam radiance estimate (module docstring): ``kernel`` "2d" | "3d", ``radii`` "fixed" |
    "knn" | "variable"; a global schedule, the frame the mean of the passes."""

    name = "bre"
    combine = MeanOfPasses
    RADII = ("fixed", "knn", "variable")

    def __init__(self, scene, *, kernel: str = "3d", radii: str = "fixed", **options):
        if kernel not in ("2d", "3d"):
            raise ValueError(f"kernel={kernel!r}: choose 2d (Jarosz et al. 2008's biweight disc) or 3d (a ball)")
        if radii not in self.RADII:
            raise ValueError(f"radii={radii!r}: choose one of {', '.join(self.RADII)}")
        self.method = vg.BRE2D if kernel == "2d" else vg.BRE3D
        self.kernel, self.radii = kernel, radii
        super().__init__(scene, **options)

    def _factor(self, pass_index: int, k: int) -> float:
        return ppm_radius2_factor(pass_index, self.alpha) ** (1.0 / k)

    def photon_radii(self, lp, sel, pass_index: int) -> np.ndarray:
        """Radii of the photons ``sel`` (vertex rows) for this pass (module docstring)."""
        f = self._factor(pass_index, self.method)
        if self.radii == "fixed" or sel.size <= self.neighbors:
            return np.full(sel.size, max(self.rv0 * f, self.r_min))
        workers = self.setup.threads or -1
        if self.radii == "knn":
            r = radii_mod.knn_radii(lp.pos[sel], self.neighbors, workers=workers)
        else:
            r = radii_mod.variable_radii(lp.pos[sel], self.neighbors, workers=workers)
        return np.maximum(r * self.volume_radius_scale * f, self.r_min)

    def build(self, lp):
        radius = np.zeros(len(lp))
        bbhs = []
        for sel in self._halves(lp, self._volume_rows(lp)):
            r = self.photon_radii(lp, sel, self._pass)
            radius[sel] = r
            b = bbh_mod.build(lp.pos[sel], r)
            bbhs.append(b._replace(order=sel[b.order]))     # the hierarchy answers vertex rows
        self._nvol = int(sum(b.order.size for b in bbhs))
        g = hashgrid.build(np.zeros((0, 3)), 1.0)
        return lp, self._surface_grids_at(lp), (g, g), tuple(bbhs), radius

    def trace_photons(self, pass_index: int):
        self._pass = pass_index
        return super().trace_photons(pass_index)

    def _surface_grids_at(self, lp):
        self._r2_now = self.r2 * ppm_radius2_factor(self._pass, self.alpha)
        saved, self.r2 = self.r2, self._r2_now
        try:
            return self._surface_grids(lp)
        finally:
            self.r2 = saved

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, sg, vgr, bb, radius = accel
        r2 = self._r2_now
        out = self._run(lp, sg, vgr, bb, radius, 2 * pass_index, np.sqrt(r2), np.zeros_like(r2))
        est = (out.phi / (math.pi * r2[None, :, :, None]) + out.phiv) / self.n_half + out.le
        self._r_now = float(np.median(radius[radius > 0])) if (radius > 0).any() else 0.0
        return _result(est, out.le, self._stats(out, lp, self._nvol))

    def pass_state(self) -> dict:
        return {"alpha": self.alpha, "mean_radius": float(np.sqrt(self._r2_now).mean()),
                "median_volume_radius": self._r_now}
