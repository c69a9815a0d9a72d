"""Gradient-domain volumetric photon mapping (``gvpm``; Gruson et al. 2018, "Gradient-Domain Volumetric
Photon Density Estimation", Sec. 4 and 6.1; PHOTONS.md Sec. 5.1-5.5 and 5.9).

VPM (:class:`gdlearn.integrators.photon.volumetric.VPM`, the point-point 3D estimate) whose every
camera path is shifted to its four neighbours and every gathered photon follows by the mixed shift
of Eq. 16 (:mod:`gdlearn.integrators.photon.gvpm_gather`): the pass writes the primal, gradient and
weighted-offset buffers of :mod:`gdlearn.integrators.gradients`, and the frame carries ``primal``
(the MIS-weighted one, :func:`gdlearn.integrators.gradients.mis_primal`: the offset paths reused,
PHOTONS.md Sec. 0.2), ``primal_base`` (VPM's own estimate, bit for bit the same photons and gather
points), ``gx``, ``gy`` for the reconstructions (``--recon l1|l2|cv|cv-weighted``), and per-pixel
shift counts ``shift_null``, ``shift_mixed``, ``shift_reconnected``, ``shift_failed`` (summed over
passes; mixed ones are reconnected too).

Only light transport ending in the medium (``transport="media"``, the setting of the paper's
experiments, PHOTONS.md E15); the full image needs GPM's surface shifts beside it and is refused.

Progressive statistics as VPM's (PHOTONS.md Sec. 1.4): per pixel R, N with the cube root, every
flux of a pixel (the base, the four D_k and S_k) sharing R and N, N driven by the base's photon count
M (all K distance samples of the pass). ``volume_radius=r, alpha=1`` keeps one fixed radius for
every pixel: each pass is then an independent estimate of the blurred image and the gradients are
unbiased for its differences (tests/test_gvpm.py). No photon subsets (E16: they would halve M).

``shift="mixed"`` (default; Eq. 16) or ``"simple"`` (every photon translated by d' - d and
reconnected). Reconnections cross null interfaces (a medium's boundary) as the base edge did
(:mod:`gdlearn.integrators.photon.gvpm_light`). Photons whose parent is specular fail their shift
(counted): the manifold walk of Sec. 4.3 is not implemented for volumes yet.
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.integrators.base import PassResult
from gdlearn.integrators.gradients import combine_gradients, mis_primal
from gdlearn.integrators.photon import gvpm_gather as gg
from gdlearn.integrators.photon.sppm import FOOTPRINT_SAMPLE
from gdlearn.integrators.photon.volumetric import VPM, reduce_radius3
from gdlearn.photons import grid as hashgrid

SHIFTS = ("mixed", "simple")


class GVPM(VPM):
    """``make("gvpm", scene, transport="media", shift="mixed", seed=0, photons_per_pass=100000,
    alpha=0.7, volume_radius=None, volume_radius_scale=1.0, neighbors=32, samples=8, effects=None,
    max_depth=None, threads=None)`` (module docstring)."""

    name = "gvpm"

    def __init__(self, scene, *, shift: str = "mixed", transport: str = "all", radii: str = "fixed", **options):
        if transport != "media":
            raise ValueError(f"gvpm: transport={transport!r} is not supported yet -- it renders light transport "
                             "ending in the medium only (the paper's setting); fix: --transport media "
                             "(transport=\"media\"), and compare against vpm/bre with --transport media")
        if shift not in SHIFTS:
            raise ValueError(f"gvpm: shift={shift!r}; choose mixed (Gruson et al. 2018, Eq. 16) or simple")
        if radii != "fixed":
            raise ValueError("gvpm: radii='knn' has no shift (the k-NN radius differs at d and d'); fix: drop "
                             "--radii (progressive per-pixel radii)")
        super().__init__(scene, transport=transport, radii="fixed", **options)
        self.shift = shift
        self.gv = gg.GvpmParams(self.vparams.samples, shift == "mixed")

    def _gvpm(self, lp, vgrids, sample0, radius):
        out = gg.allocate(self.height, self.width)
        with self.setup.parallel(self.height):
            gg.gvpm_rows(self.setup.sa, lp, vgrids, self.gather_params, self.gv, self.seed, sample0, radius, out)
        return out

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
        finally:
            self.height, self.width = h, w
        return time.perf_counter() - t0

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, _, vgrids, _ = accel
        h, w = self.height, self.width
        if pass_index == 0:
            self.Nv = np.zeros((h, w))
            self.rv = np.full((h, w), self.rv0)
            self.Dv = np.zeros((2, 9, h, w, 3))
            self.counts = np.zeros((4, h, w))
        out = self._gvpm(lp, vgrids, 2 * pass_index, self.rv)
        vol = 4.0 / 3.0 * math.pi * self.rv ** 3
        self.Dv += out.phi / vol[None, None, :, :, None]
        self.counts += out.count.sum(axis=0)
        self._mv = out.m.sum(axis=0)
        est = self.Dv / (self.n_half * (pass_index + 1))
        halves = {name: [] for name in ("primal", "primal_base", "gx", "gy")}
        for b in est:                                     # per half: (9, H, W, 3)
            gx, gy = combine_gradients(b[1:5], (1.0, 1.0))   # the MIS weights are inside the buffers
            for name, img in zip(("primal", "primal_base", "gx", "gy"), (mis_primal(b), b[0], gx, gy)):
                halves[name].append(img)
        images = {name: 0.5 * (a + b) for name, (a, b) in halves.items()}
        for i, name in enumerate(("null", "mixed", "reconnected", "failed")):
            images[f"shift_{name}"] = self.counts[i].copy()
        stats = {"light_paths": 2 * self.n_half, "light_vertices": len(lp), "volume_photons": int(self._nvol),
                 "volume_photons_gathered": int(out.m.sum()), "nonfinite_samples": int(out.bad.sum())}
        for i, name in enumerate(("null", "mixed", "reconnected", "failed")):
            stats[f"photon_shifts_{name}"] = int(out.count[:, i].sum())
        return PassResult(images=images, spp=2, halves={n: tuple(v) for n, v in halves.items()}, stats=stats)

    def update_radius(self, pass_index: int) -> None:
        self.Nv, rv = reduce_radius3(self.Nv, self.rv, self._mv, self.alpha)
        self.rv = np.maximum(rv, self.r_min)

    def pass_state(self) -> dict:
        return {"alpha": self.alpha, "mean_volume_radius": float(self.rv.mean()), "volume_radius": self.rv.copy(),
                "photon_count": self.Nv.copy()}
