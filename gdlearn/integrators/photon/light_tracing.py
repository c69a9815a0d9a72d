"""Light tracing into the medium (``lt``): an unbiased estimate of the light that ends in the medium.

The volumetric photon estimators' ``transport="media"`` image (Gruson et al. 2018's setting,
PHOTONS.md E15) holds the paths whose first non-specular vertex from the camera is a medium
scattering event. The path tracer estimates it without bias (``make("pt", transport="media")``)
but finds a volume caustic only when a phase-function sample happens to leave through the glass
towards the light: on ``scenes/volume-caustic.xml`` its relMSE floor after 65536 spp was 1.9e-3,
most of it the caustic classes. Light paths focus into the caustic on their own. This estimator
connects every volume photon to the pinhole camera (light tracing, Veach 1997, Sec. 10.2; the
t = 1 strategy of bidirectional path tracing): no kernel, no blur, so it can judge a kernel's size.

Estimator. A pixel's value is the mean radiance over its area on the image plane at distance 1
from the pinhole, ``I = (1/A_pix) int L du``. With du = dw / cos^3(theta) (theta from the optical
axis), the in-scattered radiance ``L = int_0^s T(t) sigma_s int f_p L_i dw' dt`` of the volume
rendering equation (Jarosz et al. 2008, Eq. 1) and dV = t^2 dt dw::

    I = (1/A_pix) int_{V_pix} T(c, b) sigma_s int f_p(w', c - b) L_i(b, w') dw' / (cos^3(theta) t^2) dV.

The photon records (:mod:`gdlearn.photons.records`) carry ``beta``, the sigma_s-weighted flux per
emitted light path arriving at b, so E[sum_k beta_k delta(b - b_k) delta(w - w_k)] / N = sigma_s L_i
(Jarosz et al. 2008, Eq. 4 and 11), and each photon adds to the pixel it projects into::

    beta f_p(-d_in, toward the camera) T(c, b) / (N A_pix cos^3(theta) t^2),

with the camera segment's transmittance through the media and null interfaces it crosses, and 0 if
any other surface blocks it. Only paths *seen directly* (E M ... L) are estimated: a medium seen
through glass (E S+ M ... L) needs the path tracer; :func:`specular_view_mask` marks the pixels where
the camera may look through a specular surface, so a study can leave them out or take them from pt.
A camera *inside* a medium (the fog box) makes the variance infinite: photons near the pinhole
weigh 1/t^2, and their density does not fall with t (E[w^2] ~ int dt / t^2); the mean stays right,
but pt is the reference there. The photon's light depth k and the camera segment make a path of
k + 1 segments, so the tracer stops at max_depth - 1 scattering vertices, as VPM's does. Passes
are independent (light paths of pass i use sample index i): the frame is their mean, its halves
the even and odd passes.
"""
from __future__ import annotations

import math
import time

import numpy as np

from gdlearn.integrators.base import PassResult, ProgressiveIntegrator
from gdlearn.integrators.setup import SceneSetup
from gdlearn.integrators.path.volume import shadow_transmittance
from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit_inline
from gdlearn.kernels.bsdf.dispatch import bsdf_is_delta_only, bsdf_is_null
from gdlearn.kernels.camera import CAM_H, CAM_TX, CAM_TY, CAM_W, camera_raster, camera_ray
from gdlearn.kernels.geometry import INFO_MAT, offset_origin, surface
from gdlearn.kernels.jit import block
from gdlearn.kernels.media.medium import medium_params
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.photons.records import K_MEDIUM
from gdlearn.integrators.photon.sppm import path_bound
from gdlearn.photons.trace import LightTracer, TraceParams


@block
def splat_volume_photons(sa, pos, d_in, beta, kind, obj, inv_n, out, stack):
    """Add every medium vertex of a pass's light paths to the pixel it projects into (module
    docstring); ``inv_n`` is 1 / the number of light paths emitted. Returns the photons splatted."""
    cam = sa.camera
    o = (cam[0], cam[1], cam[2])
    fwd = (cam[9], cam[10], cam[11])
    a_pix = 4.0 * cam[CAM_TX] * cam[CAM_TY] / (cam[CAM_W] * cam[CAM_H])
    zero = (0.0, 0.0, 0.0)
    n = 0
    for i in range(pos.shape[0]):
        if kind[i] != K_MEDIUM:
            continue
        b = (pos[i, 0], pos[i, 1], pos[i, 2])
        ok, fx, fy = camera_raster(cam, b)
        if not ok:
            continue
        dv = (o[0] - b[0], o[1] - b[1], o[2] - b[2])
        t2 = dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]
        t = math.sqrt(t2)
        wc = (dv[0] / t, dv[1] / t, dv[2] / t)            # from b towards the camera
        cos_t = -(wc[0] * fwd[0] + wc[1] * fwd[1] + wc[2] * fwd[2])    # > 0: camera_raster's ok says so
        tr = shadow_transmittance(sa, o, zero, b, sa.camera_medium, stack)
        if tr[0] == 0.0 and tr[1] == 0.0 and tr[2] == 0.0:
            continue
        g = medium_params(sa.media[obj[i]])[2]
        # hg_eval takes the cosine between the two directions leaving b (towards the camera and
        # towards where the light came from), as the path tracer's next-event estimate does
        ph = hg_eval(g, -(wc[0] * d_in[i, 0] + wc[1] * d_in[i, 1] + wc[2] * d_in[i, 2]))
        k = ph * inv_n / (a_pix * cos_t * cos_t * cos_t * t2)
        x, y = int(fx), int(fy)
        out[y, x, 0] += beta[i, 0] * tr[0] * k
        out[y, x, 1] += beta[i, 1] * tr[1] * k
        out[y, x, 2] += beta[i, 2] * tr[2] * k
        n += 1
    return n


@block
def _sees_specular(sa, x0, y0, grid, stack):
    """Does a primary ray of pixel (x0, y0), on a grid x grid of sub-pixel positions, meet a surface
    that is neither null nor scattering-capable (delta-only: glass, a mirror) before any other?"""
    for j in range(grid):
        for i in range(grid):
            o, d, tmax = camera_ray(sa.camera, x0 + (i + 0.5) / grid, y0 + (j + 0.5) / grid)
            for _ in range(64):
                t, prim, u, v = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0,
                                                   tmax, stack)
                if prim < 0:
                    break
                mat = sa.materials[sa.prim_info[prim, INFO_MAT]]
                if bsdf_is_delta_only(mat) and not bsdf_is_null(mat):
                    return True
                if not bsdf_is_null(mat):
                    break
                p, ng, ns = surface(sa.prims, sa.prim_info, prim, o, d, t, u, v)
                o = offset_origin(p, ng, d)
                tmax = math.inf
    return False


def specular_view_mask(sa, width: int, height: int, grid: int = 4) -> np.ndarray:
    """H x W booleans: pixels where a primary ray (of ``grid`` x ``grid`` sub-pixel positions)
    meets a specular surface before any scattering one -- where a medium may be seen through glass
    or a mirror (E S+ M paths), which light tracing into the camera cannot reach."""
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    return np.array([[_sees_specular(sa, x, y, grid, stack) for x in range(width)] for y in range(height)])


class MediumLightTracer(ProgressiveIntegrator):
    """``make("lt", scene, seed=0, photons_per_pass=100000, threads=None, max_depth=None)``: light
    transport ending in the medium and seen directly, by light tracing (module docstring).
    ``threads``: numba's threads for tracing the light paths (the splat is one thread)."""

    name = "lt"

    def __init__(self, scene, *, seed: int = 0, photons_per_pass: int = 100_000, threads=None, max_depth=None,
                 sa=None, spp_per_pass: int = 1):
        self.setup = s = SceneSetup(scene, max_depth=max_depth, threads=threads, sa=sa)
        super().__init__(s.scene, seed=seed, spp_per_pass=1)
        if not s.plan.media:
            raise ValueError("lt traces light into a participating medium, and this scene has none; fix: render it "
                             "with --integrator pt")
        self.photons_per_pass = max(1, int(photons_per_pass))
        params = TraceParams(max(0, path_bound(s) - 1), s.rr_depth, s.threshold, True, True, want_volume=True)
        self.tracer = LightTracer(s.sa, params, threads=threads)
        self.stack = np.empty(STACK_SIZE, dtype=np.int32)

    def compile(self) -> float:
        t0 = time.perf_counter()
        lp = self.tracer.trace(self.seed, 0, 0, 16)
        out = np.zeros((self.setup.height, self.setup.width, 3))
        splat_volume_photons(self.setup.sa, lp.pos, lp.d_in, lp.beta, lp.kind, lp.obj, 1.0, out, self.stack)
        return time.perf_counter() - t0

    def render_pass(self, pass_index: int) -> PassResult:
        s = self.setup
        t0 = time.perf_counter()
        lp = self.tracer.trace(self.seed, pass_index, 0, self.photons_per_pass)
        t1 = time.perf_counter()
        out = np.zeros((s.height, s.width, 3))
        n = splat_volume_photons(s.sa, lp.pos, lp.d_in, lp.beta, lp.kind, lp.obj, 1.0 / self.photons_per_pass, out,
                                 self.stack)
        t2 = time.perf_counter()
        return PassResult(images={"primal": out}, spp=1, timings={"photons": t1 - t0, "splat": t2 - t1},
                          stats={"volume_photons_splatted": int(n)}, photons=self.photons_per_pass)
