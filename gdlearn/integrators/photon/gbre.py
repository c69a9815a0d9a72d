"""The gradient-domain beam radiance estimate (``gbre``; Gruson et al. 2018, "Gradient-Domain Volumetric
Photon Density Estimation", Sec. 5.1 and 6.1; PHOTONS.md Sec. 5.6, 5.9-5.11).

The BRE (:class:`gdlearn.integrators.photon.volumetric.BRE`, point-beam) whose every camera path is
shifted to its four neighbours and every gathered photon follows (:mod:`gdlearn.integrators.photon.gbre_gather`):

* ``kernel="3d"`` (default, the paper's): a ball at each photon, the gather point uniform on the
  chord the camera beam cuts through it; the photon follows by G-VPM's mixed (default, Eq. 16) or
  simple shift, the MIS ratio carrying the offset's own chord density;
* ``kernel="2d"``: Jarosz et al. 2008's biweight disc facing the ray; the photon follows by the
  rigid ray-frame copy (:func:`gdlearn.shifts.volume_photon.ray_frame_copy`) and is reconnected.
  ``shift="mixed"`` is refused: two discs facing different rays overlap in a null set.

The frame carries, like ``gvpm``'s, ``primal`` (the MIS-weighted one with the offset paths reused,
:func:`gdlearn.integrators.gradients.mis_primal`), ``primal_base`` (the BRE's own estimate -- bit
for bit the same photons, kernels and chord points when ``subsets=False``), ``gx``, ``gy`` for the
reconstructions (``--recon``), and the shift counts ``shift_null``, ``shift_mixed``,
``shift_reconnected``, ``shift_failed``, ``shift_manifold`` (walked through a specular chain) per
camera sample (the mean of the passes, as every image).

``subsets=True`` (default, as the paper's code; PHOTONS.md Sec. 5.10): a pixel of parity
(x + y) mod 2 gathers only the photons of light paths of that parity, weighted up, for its base and
its shifts; its neighbours use the other half, and with primal reuse every pixel's primal sees
both. The radius is the BRE's global schedule (Knaus & Zwicker 2011, one radius for every photon,
r_i = r_1 prod (j + alpha) / (j + 1) to the power 1/k, k the kernel's dimension), so each pass
is an independent estimate and the frame their mean; ``volume_radius=r, alpha=1`` keeps r fixed
and the gradients unbiased for the differences of the blurred image (tests/test_gbre.py).

``walk``: a volume photon's specular chain walked exactly (default) or relaxed, as ``gvpm``'s
(:mod:`gdlearn.integrators.photon.gvpm`).

``transport="all"`` (default): the BRE's full image -- the emission the camera paths see and the
surface photon estimate at the first non-specular vertex beside the medium estimate -- with the
surface part's gradients by G-VPM's surface pass (:func:`gdlearn.integrators.photon.gvol_surface.surface_pass`:
Hua et al. 2017's shifts on the same replayed offset camera paths, photon edges through media and
null interfaces), at the BRE's surface radius of the pass (its global schedule per pixel, so every
pass stays an independent estimate); the emission and its gradients are ``emission``,
``emission_gx``, ``emission_gy`` and the surface shift counts ``shift_surface_reconnected``,
``shift_surface_manifold``, ``shift_surface_failed``. The surface part gathers every photon of its
half (no subsets: they are a device of the beam gather). ``transport="media"``: the medium part
alone, the paper's experiments (PHOTONS.md E15). Fixed global radii only: a photon's k-NN or
variable radius is not defined at its shifted position.

The first volume radius is ``VOLUME_RADIUS_SCALE`` (0.1) times the BRE's default (the median
distance to the ``neighbors``-th nearest volume photon), half of G-VPM's
(``gvpm.VOLUME_RADIUS_SCALE``, where the reasons are: the gradients remove noise, not the
kernel's blur). Measured at equal time (128 x 128, 20 s, 3 seeds, 3D kernel, against unbiased
references; benchmarks/README.md, "The walk's start and G-BRE's radius"): ``gbre+l1`` from 0.1 of
the default had the lowest relMSE of 0.07, 0.1, 0.14 and 0.2 on the volume caustic, and beat 0.2 on
the fog box and the spot light; the BRE's (3D) was lowest at 0.2 of 0.1-0.3 on all three.
"""
from __future__ import annotations

import math
import time

import numpy as np

from gdlearn.integrators.base import PassResult
from gdlearn.integrators.gradients import pass_halves
from gdlearn.integrators.photon import gbre_gather as gb
from gdlearn.integrators.photon import gvpm_gather as gg
from gdlearn.integrators.path.gpt_surface.manifold import manifold_table
from gdlearn.integrators.photon.gvol_surface import SURFACE_COUNTS, surface_pass
from gdlearn.integrators.photon.photon_manifold import relaxed_walk
from gdlearn.integrators.photon.sppm import FOOTPRINT_SAMPLE
from gdlearn.integrators.photon.volumetric import BRE
from gdlearn.photons import bbh as bbh_mod
from gdlearn.photons import grid as hashgrid

SHIFTS = ("mixed", "simple")
#: the first volume radius of gbre, x the BRE's default (module docstring)
VOLUME_RADIUS_SCALE = 0.1
COUNTS = ("null", "mixed", "reconnected", "failed", "manifold")     # gvpm_gather.C_*


def subset_weights(n_half: int, subsets: bool) -> np.ndarray:
    """wsub[hh, g]: the light paths of half hh over those of parity g among them (half hh holds paths
    hh n .. (hh + 1) n - 1, n = ``n_half``), so the subset's sum is unbiased for the half's (2 for an
    even n; an odd n leaves one parity one path more). All ones without subsets."""
    w = np.ones((2, 2))
    if subsets:
        for hh in range(2):
            lo, hi = hh * n_half, (hh + 1) * n_half
            for g in range(2):
                count = (hi - g + 1) // 2 - (lo - g + 1) // 2       # i in [lo, hi) with i = g mod 2
                w[hh, g] = n_half / count if count > 0 else 0.0
    return w


class GBRE(BRE):
    """``make("gbre", scene, transport="all", kernel="3d", shift=None, subsets=True, walk="exact", seed=0,
    photons_per_pass=100000, alpha=0.7, radius=None, radius_scale=1.0, volume_radius=None,
    volume_radius_scale=0.1, neighbors=32, effects=None, max_depth=None, threads=None)`` (module
    docstring; ``radius``: the surface part's initial radius, transport="all" only); ``shift`` None is "mixed" for
    the 3D kernel and the ray-frame copy ("simple") for the 2D one."""

    name = "gbre"

    def __init__(self, scene, *, kernel: str = "3d", shift: str | None = None, subsets: bool = True,
                 walk: str = "exact", transport: str = "all", radii: str = "fixed",
                 volume_radius_scale: float = VOLUME_RADIUS_SCALE, **options):
        if shift is None:
            shift = "mixed" if kernel == "3d" else "simple"
        if shift not in SHIFTS:
            raise ValueError(f"gbre: shift={shift!r}; choose mixed (Gruson et al. 2018, Eq. 16; 3d kernel) or simple")
        if kernel == "2d" and shift == "mixed":
            raise ValueError("gbre: the mixed shift needs a 3D kernel -- two discs facing different camera rays "
                             "overlap in a null set (Gruson et al. 2018, Sec. 5.1); fix: --kernel 3d, or "
                             "--shift simple with --kernel 2d (the rigid ray-frame copy)")
        if radii != "fixed":
            raise ValueError(f"gbre: radii={radii!r} has no shift (a photon's k-NN or variable radius is not "
                             "defined where the shift moves it); fix: drop --radii (one global radius schedule)")
        super().__init__(scene, kernel=kernel, transport=transport, radii="fixed",
                         volume_radius_scale=volume_radius_scale, **options)
        self.shift, self.subsets = shift, bool(subsets)
        self.gp = gb.GbreParams(self.method, shift == "mixed", self.subsets, relaxed_walk("gbre", walk))
        self.walk = walk
        self.wsub = subset_weights(self.n_half, self.subsets)
        self.mtab = manifold_table(scene, self.setup.sa)     # both parts walk specular chains

    def _gbre(self, lp, bbhs, r, sample0, h, w):
        out = gg.allocate(h, w)
        with self.setup.parallel(h):
            gb.gbre_rows(self.setup.sa, lp, bbhs, self.mtab, float(r), self.gather_params, self.gp, self.wsub, self.seed,
                         sample0, out)
        return out

    def compile(self) -> float:
        t0 = time.perf_counter()
        super().compile()
        lp = self.tracer.trace(self.seed, 0, 0, 4)
        b = bbh_mod.build(np.zeros((0, 3)), np.zeros(0))
        self._gbre(lp, (b, b, b, b), 0.1, FOOTPRINT_SAMPLE, 2, 2)
        if self.vparams.surfaces:
            g = hashgrid.build(np.zeros((0, 3)), 1.0)
            surface_pass(self.setup, lp, (g, g), self.mtab, self.gather_params, self.seed, FOOTPRINT_SAMPLE,
                         np.full((2, 2), 0.1))
        return time.perf_counter() - t0

    def build(self, lp):
        """Per half, one hierarchy per light-path parity (subsets) or the half's own, twice."""
        bbhs = []
        r = 0.0
        for sel in self._halves(lp, self._volume_rows(lp)):
            radius = self.photon_radii(lp, sel, self._pass)
            r = float(radius[0]) if radius.size else max(self.rv0 * self._factor(self._pass, self.method), self.r_min)
            parts = [sel[lp.path[sel] % 2 == g] for g in range(2)] if self.subsets else [sel]
            for p in parts:
                b = bbh_mod.build(lp.pos[p], np.full(p.size, r))
                bbhs.append(b._replace(order=p[b.order]))     # the hierarchy answers vertex rows
            if not self.subsets:
                bbhs.append(bbhs[-1])
        self._nvol = int(sum(s.size for s in self._halves(lp, self._volume_rows(lp))))
        return lp, tuple(bbhs), r, self._surface_grids_at(lp)

    def _surface(self, lp, sgrids, pass_index):
        """The surface part of the pass at the BRE's radius of this pass: (photon density + emission
        buffers, (2, 9, H, W, 3) each, per light path of a half), and the GpmOut."""
        r2 = self._r2_now
        out = surface_pass(self.setup, lp, sgrids, self.mtab, self.gather_params, self.seed, 2 * pass_index,
                           np.sqrt(r2))
        return out.phi / (math.pi * r2[None, None, :, :, None] * self.n_half), out.le, out

    def gather(self, accel, pass_index: int) -> PassResult:
        lp, bbhs, r, sgrids = accel
        out = self._gbre(lp, bbhs, r, 2 * pass_index, self.height, self.width)
        est = out.phi / self.n_half                           # (2, 9, H, W, 3): the kernel is inside
        if self.vparams.surfaces:
            dens, le, sout = self._surface(lp, sgrids, pass_index)
            halves = {**pass_halves(est + dens + le, ("primal", "primal_base", "gx", "gy")),
                      **pass_halves(le, ("emission", None, "emission_gx", "emission_gy"))}
        else:
            halves = pass_halves(est, ("primal", "primal_base", "gx", "gy"))
        for i, name in enumerate(COUNTS):
            halves[f"shift_{name}"] = [out.count[0, i], out.count[1, i]]
        if self.vparams.surfaces:
            for name, i in SURFACE_COUNTS:
                halves[f"shift_surface_{name}"] = [sout.count[0, i], sout.count[1, i]]
        images = {name: 0.5 * (a + b) for name, (a, b) in halves.items()}
        self._r_now = r
        stats = {"light_paths": 2 * self.n_half, "light_vertices": len(lp), "volume_photons": self._nvol,
                 "volume_photons_gathered": int(out.m.sum()), "nonfinite_samples": int(out.bad.sum())}
        for i, name in enumerate(COUNTS):
            stats[f"photon_shifts_{name}"] = int(out.count[:, i].sum())
        if self.vparams.surfaces:
            for name, i in SURFACE_COUNTS:
                stats[f"surface_photon_shifts_{name}"] = int(sout.count[:, i].sum())
            stats["photons_gathered"] = int(sout.m.sum())
            stats["nonfinite_samples"] += int(sout.bad.sum())
        return PassResult(images=images, spp=2, halves={n: tuple(v) for n, v in halves.items()}, stats=stats)

    def pass_state(self) -> dict:
        state = {"alpha": self.alpha, "volume_radius": self._r_now}
        if self.vparams.surfaces:
            state["mean_radius"] = float(np.sqrt(self._r2_now).mean())
        return state
