"""Gradient-domain photon mapping (``gpm``; Hua et al. 2017, "Gradient-Domain Photon Density
Estimation"; PHOTONS.md Sec. 2).

SPPM (:mod:`gdlearn.integrators.photon.sppm`) whose every gather point is shifted to its four
neighbours, its photons following by the hybrid shift of :mod:`gdlearn.integrators.photon.gpm_gather`:
the pass writes the primal, gradient and weighted-offset buffers of
:mod:`gdlearn.integrators.gradients`, and the frame carries ``primal``, ``gx`` and ``gy`` for the
reconstructions (``--recon l1|l2|cv|cv-weighted``).

Progressive statistics (PHOTONS.md Sec. 1.4; Hua et al. 2017 Sec. 4.3): every flux of a gather
point -- the base, the four D_k and the four S_k -- shares the pixel's radius R and count N, and
N is driven by the base's photon count alone; each accumulates in SPPM's density form
``sum_i Phi_i / (pi R_i^2)``. alpha = 0.9 by default, the paper's. The pass's two halves (light
paths j < n and j >= n, each gathered by its own camera sample) share R and N, so their spread
estimates the variance the weighted reconstructions need (the online variance of a progressive
estimate would mix passes of different radii).

The kernel's first radius is ``radius_scale`` = ``RADIUS_SCALE`` (0.35) times the pixel footprint,
not the footprint itself as in SPPM and Hua et al. 2017 (Sec. 5, "initialized using ray
differentials, to approximate the projected pixel size"). A kernel estimator's error is the blur of
its radius (a bias) plus its noise; the gradients hold the noise down, so at the footprint
``gpm``'s error is almost all blur, and a smaller kernel trades a little more noise for
almost all of the blur (Gruson et al. 2018, Sec. 6.3 and Fig. 11: the gradient domain "could be just safe
to set a small kernel size"). Measured with :func:`gdlearn.experiments.metrics.bias_variance`
(``benchmarks/bench_gpm.py --sweep``, 128x128, 20 s, 3 seeds; benchmarks/README.md): on the Cornell
box gpm+L1's relMSE is 1.93e-3 at the footprint, of it 1.69e-3 squared bias, and 5.3e-4 at 0.35
(0.25: 5.7e-4, 0.5: 6.4e-4); SPPM's is lowest at the footprint (1.94e-3; 2.7e-3 at 0.7, 2.1e-3 at
1.4, 8.7e-3 at 0.35), so SPPM keeps it.

The kernel radius of an offset is the base gather point's (Sec. 2.2); with per-pixel radii the
gradient between p and q then mixes estimates at r_p and r_q, which the radius reduction makes
consistent. At one fixed radius for every pixel (``radius=r, alpha=1``) the gradients are unbiased
for the differences of the blurred image (``tests/test_gpm.py``).

The primal image is the MIS-weighted one (:func:`gdlearn.integrators.gradients.mis_primal`; the
base estimate alone is ``primal_base``). ``emission`` is the part the camera paths see directly
or through specular chains (emitters, added exactly as in SPPM), with its gradients
``emission_gx``, ``emission_gy`` (the replayed camera paths, balance weight 1/2): the
reconstructions leave it out and add it back (:mod:`gdlearn.experiments.solvers`). ``shift_reconnected``, ``shift_manifold`` and
``shift_failed`` count the photon shifts per base pixel (summed over passes): reconnected to a
diffuse or glossy parent or the emitter, moved by the manifold walk (a parent on a delta chain of
analytic shapes, Eq. 7-8), or failed (weight 1, the primal difference; unbiased, just noisier --
glossy chains, Eq. 9-10, are not walked and fail).

Refused: media (``vpm`` / ``bre`` instead), ``direct="nee"`` (its emitter sample would need a
shift of its own).
"""
from __future__ import annotations

import numpy as np

from gdlearn.integrators.base import PassResult
from gdlearn.integrators.gradients import pass_halves
from gdlearn.integrators.path.gpt_surface.manifold import manifold_table
from gdlearn.integrators.photon.gpm_gather import FAILED, MANIFOLD, RECONNECTED, allocate, gpm_rows
from gdlearn.integrators.photon.sppm import FOOTPRINT_SAMPLE, SurfacePhotonMapper, accumulate_density, reduce_radius
from gdlearn.photons import grid as hashgrid


#: the first kernel radius in pixel footprints (module docstring: the gradients afford a smaller kernel)
RADIUS_SCALE = 0.35


class GPM(SurfacePhotonMapper):
    """``make("gpm", scene, seed=0, photons_per_pass=100000, alpha=0.9, radius=None,
    radius_scale=0.35, effects=None, max_depth=None, threads=None)`` (module docstring)."""

    name = "gpm"

    def __init__(self, scene, *, alpha: float = 0.9, radius_scale: float = RADIUS_SCALE, direct: str = "photons",
                 **options):
        if direct != "photons":
            raise ValueError("gpm estimates the direct light with photons (a gradient of the emitter sample at the "
                             "gather point would need a shift of its own); fix: drop direct=/--direct")
        super().__init__(scene, alpha=alpha, radius_scale=radius_scale, direct="photons", **options)
        self.mtab = manifold_table(scene, self.setup.sa)     # analytic specular shapes: the manifold branch

    def _gpm(self, light_paths, grids, sample0, radius):
        out = allocate(self.height, self.width)
        with self.setup.parallel(self.height):
            gpm_rows(self.setup.sa, light_paths, grids, self.mtab, self.gather_params, self.seed, sample0, radius, out)
        return out

    def compile(self) -> float:
        import time
        t0 = time.perf_counter()
        super().compile()
        lp = self.tracer.trace(self.seed, 0, 0, 4)
        g = hashgrid.build_rows(lp.pos, lp.photons, 1.0)
        h, w = self.height, self.width
        self.height, self.width = 2, 2
        try:
            self._gpm(lp, (g, g), FOOTPRINT_SAMPLE, np.full((2, 2), 0.1))
        finally:
            self.height, self.width = h, w
        return time.perf_counter() - t0

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, grids = accel
        out = self._gpm(lp, grids, 2 * pass_index, np.sqrt(self.r2))
        h, w = self.height, self.width
        if pass_index == 0:
            self.N = np.zeros((h, w))
            self.D = np.zeros((2, 9, h, w, 3))
            self.E = np.zeros((2, 9, h, w, 3))
            self.counts = np.zeros((3, h, w))
        accumulate_density(self.D, out.phi, np.broadcast_to(self.r2, (2, 9, h, w)))
        self.E += out.le
        self.counts += out.count.sum(axis=0)
        self._m = out.m.sum(axis=0)
        k = pass_index + 1
        emis = self.E / k
        halves = {**pass_halves(self.D / (self.n_half * k) + emis, ("primal", "primal_base", "gx", "gy")),
                  **pass_halves(emis, ("emission", None, "emission_gx", "emission_gy"))}
        images = {name: 0.5 * (a + b) for name, (a, b) in halves.items()}
        images["shift_reconnected"] = self.counts[RECONNECTED].copy()
        images["shift_failed"] = self.counts[FAILED].copy()
        images["shift_manifold"] = self.counts[MANIFOLD].copy()
        stats = {"light_paths": 2 * self.n_half, "light_vertices": len(lp), "photons_stored": self._nphotons,
                 "gather_points": int((out.foot > 0).sum()), "photons_gathered": int(out.m.sum()),
                 "nonfinite_samples": int(out.bad.sum()),
                 "photon_shifts_reconnected": int(out.count[:, RECONNECTED].sum()),
                 "photon_shifts_failed": int(out.count[:, FAILED].sum()),
                 "photon_shifts_manifold": int(out.count[:, MANIFOLD].sum())}
        return PassResult(images=images, spp=2, halves={n: tuple(v) for n, v in halves.items()}, stats=stats)

    def update_radius(self, pass_index: int) -> None:
        self.N, self.r2 = reduce_radius(self.N, self.r2, self._m, self.alpha)

    def pass_state(self) -> dict:
        return {"alpha": self.alpha, "radius": np.sqrt(self.r2), "photon_count": self.N.copy(),
                "mean_radius": float(np.sqrt(self.r2).mean())}
