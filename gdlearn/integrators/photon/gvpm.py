"""Gradient-domain volumetric photon mapping (``gvpm``; Gruson et al. 2018, "Gradient-Domain Volumetric
Photon Density Estimation", Sec. 4 and 6.1; PHOTONS.md Sec. 5.1-5.5 and 5.9).

VPM (:class:`gdlearn.integrators.photon.volumetric.VPM`, the point-point 3D estimate) whose every
camera path is shifted to its four neighbours and every gathered photon follows by the mixed shift
of Eq. 16 (:mod:`gdlearn.integrators.photon.gvpm_gather`): the pass writes the primal, gradient and
weighted-offset buffers of :mod:`gdlearn.integrators.gradients`, and the frame carries ``primal``
(the MIS-weighted one, :func:`gdlearn.integrators.gradients.mis_primal`: the offset paths reused,
PHOTONS.md Sec. 0.2), ``primal_base`` (VPM's own estimate, bit for bit the same photons and gather
points), ``gx``, ``gy`` for the reconstructions (``--recon l1|l2|cv|cv-weighted``), and per-pixel
shift counts ``shift_null``, ``shift_mixed``, ``shift_reconnected``, ``shift_failed``,
``shift_manifold`` (summed over passes; mixed ones are reconnected too).

``transport="all"`` (default): VPM's full image -- the emission the camera paths see, the surface
photon estimate at the first non-specular vertex (through the media before it) and the medium
estimate along the camera beams -- with the surface part's gradients by GPM's shifts
(:mod:`gdlearn.integrators.photon.gvol_surface`: the same replayed offset camera path as the
medium part, the transmittance along the offset's own beams in its f, photon edges through media
and null interfaces with a medium parent's phase function in the reconnection). Both passes write
the same L / D_k / S_k layout with one MIS convention and are summed before the frame's images.
``transport="media"``: the medium part alone, the setting of the paper's experiments (PHOTONS.md E15).

Progressive statistics as VPM's (PHOTONS.md Sec. 1.4), each part its own: the medium part per pixel
R, N with the cube root, every flux of a pixel (the base, the four D_k and S_k) sharing R and N, N
driven by the base's photon count M (all K distance samples of the pass); the surface part GPM's
(Hua et al. 2017, Sec. 4.3: R^2, N per pixel, shared by the base and shifted fluxes, driven by the
base's M). One alpha for both, as VPM. ``volume_radius=r, radius=r_s, alpha=1`` keeps fixed radii:
each pass is then an independent estimate of the blurred image and the gradients are unbiased for
its differences (tests/test_gvpm.py, tests/test_gvpm_full.py). No photon subsets (E16: they would
halve M). Surface shift counts: ``shift_surface_reconnected``, ``shift_surface_manifold``,
``shift_surface_failed``; the emission and its gradients are ``emission``, ``emission_gx``,
``emission_gy`` (as GPM: the reconstructions leave it out and add it back).

The first volume radius is ``VOLUME_RADIUS_SCALE`` (0.2) times VPM's default (the median distance
to the ``neighbors``-th nearest volume photon), unless ``volume_radius`` or ``volume_radius_scale``
says otherwise. The gradients and the reconstruction remove noise, not the kernel's blur, so the
gradient estimators afford a smaller kernel than their primal: at equal time (128 x 128, 20 s,
3 seeds, against unbiased references: pt or light tracing with ``transport="media"``) ``gvpm+l1``'s
relMSE was lowest at 0.2 of the default on the spot light, the fog box and the volume caustic, and
VPM's at 0.35, both mostly blur at the default (benchmarks/README.md, "The volume radius against
unbiased references"; Gruson et al. 2018, Sec. 6.3 and Fig. 11, find the gradient domain less
sensitive to the kernel's size). A smaller kernel also holds fewer photons to shift: a cheaper pass.

``shift="mixed"`` (default; Eq. 16) or ``"simple"`` (every photon translated by d' - d and
reconnected). Reconnections cross null interfaces (a medium's boundary) as the base edge did
(:mod:`gdlearn.integrators.photon.gvpm_light`). A volume photon whose parent is specular (the cone
under a glass ball: scenes/volume-caustic.xml) takes the manifold walk of Sec. 4.3 when its chain
lies in vacuum (:func:`gdlearn.integrators.photon.photon_manifold.manifold_volume_photon`), and fails
otherwise; surface photons take GPM's manifold walk on the same condition
(:mod:`gdlearn.integrators.photon.gvol_surface_light`). The walk converges and walks back
(``walk="exact"``, the default), so a fixed radius keeps the gradients unbiased; ``walk="relaxed"``
is the paper's default (Sec. 6.1), accepted once the chain it traces ends inside the offset
photon's kernel and without the walk back -- biased, consistent as the radius shrinks, and
measured worse at equal time on the volume caustic (benchmarks/README.md, "The relaxed walk").
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.integrators.base import PassResult
from gdlearn.integrators.gradients import pass_halves
from gdlearn.integrators.path.gpt_surface.manifold import manifold_table
from gdlearn.integrators.photon import gvpm_gather as gg
from gdlearn.integrators.photon.gvol_surface import SURFACE_COUNTS, surface_pass
from gdlearn.integrators.photon.photon_manifold import relaxed_walk
from gdlearn.integrators.photon.sppm import FOOTPRINT_SAMPLE, accumulate_density, reduce_radius
from gdlearn.integrators.photon.volumetric import VPM, reduce_radius3
from gdlearn.photons import grid as hashgrid

SHIFTS = ("mixed", "simple")
#: the first volume radius of gvpm, x VPM's default (module docstring; gbre has its own)
VOLUME_RADIUS_SCALE = 0.2
#: the medium part's shift counts (gvpm_gather.C_*)
_MEDIUM_COUNTS = ("null", "mixed", "reconnected", "failed", "manifold")


class GVPM(VPM):
    """``make("gvpm", scene, transport="all", shift="mixed", walk="exact", seed=0, photons_per_pass=100000,
    alpha=0.7, radius=None, radius_scale=1.0, volume_radius=None, volume_radius_scale=0.2,
    neighbors=32, samples=8, effects=None, max_depth=None, threads=None)`` (module docstring)."""

    name = "gvpm"

    def __init__(self, scene, *, shift: str = "mixed", walk: str = "exact", transport: str = "all",
                 radii: str = "fixed", volume_radius_scale: float = VOLUME_RADIUS_SCALE, **options):
        if shift not in SHIFTS:
            raise ValueError(f"gvpm: shift={shift!r}; choose mixed (Gruson et al. 2018, Eq. 16) or simple")
        if radii != "fixed":
            raise ValueError("gvpm: radii='knn' has no shift (the k-NN radius differs at d and d'); fix: drop "
                             "--radii (progressive per-pixel radii)")
        super().__init__(scene, transport=transport, radii="fixed", volume_radius_scale=volume_radius_scale, **options)
        self.shift = shift
        self.gv = gg.GvpmParams(self.vparams.samples, shift == "mixed", relaxed_walk("gvpm", walk))
        self.walk = walk
        self.mtab = manifold_table(scene, self.setup.sa)     # both parts walk specular chains

    def _gvpm(self, lp, vgrids, sample0, radius):
        out = gg.allocate(self.height, self.width)
        with self.setup.parallel(self.height):
            gg.gvpm_rows(self.setup.sa, lp, vgrids, self.mtab, self.gather_params, self.gv, self.seed, sample0, radius,
                         out)
        return out

    def _surface(self, lp, sgrids, sample0, radius):
        return surface_pass(self.setup, lp, sgrids, self.mtab, self.gather_params, self.seed, sample0, radius)

    def compile(self) -> float:
        import time
        t0 = time.perf_counter()
        super().compile()
        lp = self.tracer.trace(self.seed, 0, 0, 4)
        g = hashgrid.build(np.zeros((0, 3)), 1.0)
        h, w = self.height, self.width
        self.height, self.width = 2, 2
        try:
            self._gvpm(lp, (g, g), FOOTPRINT_SAMPLE, np.full((2, 2), 0.1))
            if self.vparams.surfaces:
                self._surface(lp, (g, g), FOOTPRINT_SAMPLE, np.full((2, 2), 0.1))
        finally:
            self.height, self.width = h, w
        return time.perf_counter() - t0

    def _start(self):
        h, w = self.height, self.width
        self.Nv = np.zeros((h, w))
        self.rv = np.full((h, w), self.rv0)
        self.Dv = np.zeros((2, 9, h, w, 3))
        self.counts = np.zeros((len(_MEDIUM_COUNTS), h, w))
        # the surface part (zeros under transport="media": the sums below need no branch)
        self.N = np.zeros((h, w))
        self.D = np.zeros((2, 9, h, w, 3))
        self.E = np.zeros((2, 9, h, w, 3))
        self.scounts = np.zeros((3, h, w))

    def _surface_step(self, lp, sgrids, pass_index):
        """The surface pass into D (SPPM's density form at this pass's R^2), E and the counts."""
        h, w = self.height, self.width
        out = self._surface(lp, sgrids, 2 * pass_index, np.sqrt(self.r2))
        accumulate_density(self.D, out.phi, np.broadcast_to(self.r2, (2, 9, h, w)))
        self.E += out.le
        self.scounts += out.count.sum(axis=0)
        self._m = out.m.sum(axis=0)
        return out

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, sgrids, vgrids, _ = accel
        if pass_index == 0:
            self._start()
        out = self._gvpm(lp, vgrids, 2 * pass_index, self.rv)
        vol = 4.0 / 3.0 * math.pi * self.rv ** 3
        self.Dv += out.phi / vol[None, None, :, :, None]
        self.counts += out.count.sum(axis=0)
        self._mv = out.m.sum(axis=0)
        sout = self._surface_step(lp, sgrids, pass_index) if self.vparams.surfaces else None
        k = pass_index + 1
        # as VPM's frame: (surface + medium densities) / light paths + emission, per half
        est = (self.D + self.Dv) / (self.n_half * k) + self.E / k
        halves = pass_halves(est, ("primal", "primal_base", "gx", "gy"))
        if self.vparams.surfaces:
            halves.update(pass_halves(self.E / k, ("emission", None, "emission_gx", "emission_gy")))
        images = {name: 0.5 * (a + b) for name, (a, b) in halves.items()}
        for i, name in enumerate(_MEDIUM_COUNTS):
            images[f"shift_{name}"] = self.counts[i].copy()
        stats = {"light_paths": 2 * self.n_half, "light_vertices": len(lp), "volume_photons": int(self._nvol),
                 "volume_photons_gathered": int(out.m.sum()), "nonfinite_samples": int(out.bad.sum())}
        for i, name in enumerate(_MEDIUM_COUNTS):
            stats[f"photon_shifts_{name}"] = int(out.count[:, i].sum())
        if sout is not None:
            for name, i in SURFACE_COUNTS:
                images[f"shift_surface_{name}"] = self.scounts[i].copy()
                stats[f"surface_photon_shifts_{name}"] = int(sout.count[:, i].sum())
            stats["photons_gathered"] = int(sout.m.sum())
            stats["nonfinite_samples"] += int(sout.bad.sum())
        return PassResult(images=images, spp=2, halves={n: tuple(v) for n, v in halves.items()}, stats=stats)

    def update_radius(self, pass_index: int) -> None:
        self.Nv, rv = reduce_radius3(self.Nv, self.rv, self._mv, self.alpha)
        self.rv = np.maximum(rv, self.r_min)
        if self.vparams.surfaces:
            self.N, self.r2 = reduce_radius(self.N, self.r2, self._m, self.alpha)

    def pass_state(self) -> dict:
        state = {"alpha": self.alpha, "mean_volume_radius": float(self.rv.mean()), "volume_radius": self.rv.copy(),
                 "photon_count": self.Nv.copy()}
        if self.vparams.surfaces:
            state.update(mean_radius=float(np.sqrt(self.r2).mean()), radius=np.sqrt(self.r2),
                         surface_photon_count=self.N.copy())
        return state
