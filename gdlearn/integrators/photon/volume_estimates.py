"""Medium radiance along a camera beam from volume photons: VPM (point-point) and the BRE (point-beam).

Every estimator here estimates the beam integral of the volume rendering equation (Jarosz et al.
2008, Eq. 1 and 5), ``int_0^s T(t) sigma_s L_i(x_t, w) dt``, from volume photons whose power
``beta`` already carries sigma_s (records module: the albedo weight of the collision), so a
photon contributes ``rho(d_cam, d_in) beta`` times a kernel: the in-scattered radiance
``sigma_s L_i`` of Jarosz et al. 2008, Eq. 4, is ``sum_p rho beta_p K(x - x_p)`` per emitted path.
The phase function is Mitsuba's HG with wi = -d_cam (back along the camera ray) and wo = -d_in
(towards where the light came from): cos = d_cam . d_in (:mod:`gdlearn.kernels.media.phase`).

A photon counts only on a beam in its own medium (a kernel straddling a boundary would otherwise
mix two media's sigma_s; the bias is O(r) at the boundary and vanishes with the radius), when the
merged path fits max_depth (camera surface vertices m, photon depth k: m + 1 + k segments), and
when the effects plan wants the merged path's class.

* ``vpm_beam`` -- VPM, the point-point estimate (Jarosz et al. 2008, Eq. 3-4; its progressive
  form of Gruson et al. 2018, Sec. 6.1 and Eq. 14): K distance samples per camera path, sample k
  on a beam chosen with probability proportional to the beam's camera weight, at distance
  t ~ sigma e^(-sigma t) / (1 - e^(-sigma s)) (the truncated exponential, stratified: u = (k + xi) / K),
  each gathering the photons in a ball of radius r (uniform kernel 3 / (4 pi r^3)). With K
  samples this is the exponentially stepped ray march of Jarosz's Eq. 3 with a random offset, an
  unbiased estimate of the blurred integral at any K. With ``knn`` the radius at each sample is
  the distance to its k-th nearest photon (``knn_point``): Jarosz's conventional estimate,
  biased at any photon count unless k grows with it, and the only one whose blur adapts to the density.
* ``bre_beam`` -- the beam radiance estimate (Jarosz et al. 2008, Eq. 18-21): every photon
  whose disc (2D) or ball (3D) the beam crosses, found by the bounding-box hierarchy
  (:mod:`gdlearn.photons.bbh`), with its own radius r_i:

  - 2D (Eq. 21, with the erratum of PHOTONS.md E3: the condition t_i in (0, s), T at the projected
    point): ``rho beta T(t_i) K2(d_i / r_i) / r_i^2``, K2(x) = 3 / pi (1 - x^2)^2 -- Silverman's
    biweight, normalised over the disc (int K2 2 pi x dx = 1);
  - 3D (the uniform ball of Gruson et al. 2018, Sec. 5.1, PHOTONS.md Sec. 3.7): one point t drawn
    uniformly on the chord [t_i - D, t_i + D], D = sqrt(r_i^2 - d_i^2), weight 2 D T(t) / (4/3 pi r_i^3)
    if t lies on the beam: an unbiased estimate of the line integral of the 3D kernel. The
    estimator multiplies by the chord length instead of dividing by its pdf, so a chord of
    length 0 (a photon on the kernel boundary) weighs 0, not 0/0: no floor is needed.

Transmittance is per channel; the sampling density uses the channels' mean extinction (the pdf is
exact for what is sampled, so the estimate stays unbiased for RGB media; thin media through expm1
and log1p in :func:`gdlearn.kernels.media.medium.sample_distance_truncated_1`, uniform as sigma -> 0).

Random numbers (pixel sample h): VPM sample k takes dims ``D_VOL + 2 k + {0 beam, 1 distance}``;
the BRE-3D chord point of photon row v on beam b takes ``D_CHORD + b 2^32 + v``.
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.kernels.media.medium import medium_params, sample_distance_truncated_1, transmittance
from gdlearn.kernels.media.phase import hg_eval
from gdlearn.kernels.rng import rand_at
from gdlearn.kernels.vec import dot
from gdlearn.kernels.jit import block, inlined
from gdlearn.photons import bbh as bbh_mod
from gdlearn.photons.grid import query as grid_query
from gdlearn.integrators.photon.camera_beams import BEAM_D, BEAM_MED, BEAM_O, BEAM_S, BEAM_W
from gdlearn.integrators.photon.gather import _class_ok

D_VOL = 1 << 21
D_CHORD = 1 << 24
#: BRE kernels
KERNEL_2D, KERNEL_3D = 2, 3
INV_PI = 1.0 / math.pi


@inlined
def ball_volume(r):
    """4/3 pi r^3 in float64 (late progressive radii are small: r^3 of 1e-4 is still exact)."""
    return 4.0 / 3.0 * math.pi * r * r * r


@inlined
def biweight(x2):
    """Silverman's 2D biweight K2 at x^2 = (d / r)^2 (Jarosz et al. 2008, Eq. 21): 3/pi (1 - x^2)^2."""
    if x2 >= 1.0:
        return 0.0
    a = 1.0 - x2
    return 3.0 * INV_PI * a * a


@inlined
def _admit(lp, v, prm, medium, m, state):
    """Does volume photon row v count on a beam in ``medium`` after m camera surface vertices?"""
    if lp.medium[v] != medium:
        return False
    if lp.depth[v] + m + 1 > prm.max_depth:
        return False
    if prm.filter_classes and not _class_ok(lp, v, state, prm.mask):
        return False
    return True


@block
def vpm_point(lp, grid, prm, x, d_cam, medium, g, r, m, state, buf):
    """(sum of rho beta over the photons within r of x, their count): Jarosz et al. 2008, Eq. 4
    without the kernel's 1 / (4/3 pi r^3). ``buf`` holds the grid's candidates (as many as it has points)."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    cnt = 0
    for i in range(min(grid_query(grid, x, r, buf), buf.shape[0])):
        v = buf[i]
        if not _admit(lp, v, prm, medium, m, state):
            continue
        cnt += 1
        ph = hg_eval(g, d_cam[0] * lp.d_in[v, 0] + d_cam[1] * lp.d_in[v, 1] + d_cam[2] * lp.d_in[v, 2])
        a0 += ph * lp.beta[v, 0]
        a1 += ph * lp.beta[v, 1]
        a2 += ph * lp.beta[v, 2]
    return (a0, a1, a2), cnt


@block
def _nearest(lp, grid, prm, x, medium, r, m, state, knn, kd, kv, buf):
    """The (at most) knn nearest admitted photons strictly within r of x, sorted: squared distances
    in kd[:n], rows in kv[:n]; returns n."""
    n = 0
    for i in range(min(grid_query(grid, x, r, buf), buf.shape[0])):
        v = buf[i]
        dx = lp.pos[v, 0] - x[0]
        dy = lp.pos[v, 1] - x[1]
        dz = lp.pos[v, 2] - x[2]
        d2 = dx * dx + dy * dy + dz * dz
        if (n == knn and d2 >= kd[n - 1]) or not _admit(lp, v, prm, medium, m, state):
            continue
        j = n if n < knn else knn - 1     # insertion into the sorted list, the largest drops out
        while j > 0 and kd[j - 1] > d2:
            kd[j] = kd[j - 1]
            kv[j] = kv[j - 1]
            j -= 1
        kd[j] = d2
        kv[j] = v
        n = min(n + 1, knn)
    return n


@block
def knn_point(lp, grid, prm, x, d_cam, medium, g, knn, rmax, m, state, kd, kv, buf):
    """(sum of rho beta over the knn nearest photons, their count, the radius r_k): Jarosz et al.
    2008, Eq. 4 with the k-nearest-neighbour radius, the distance to the knn-th photon (all knn
    photons counted), or rmax where fewer lie within rmax. The search grows from one grid cell,
    doubling: once knn photons lie within r, they are the knn nearest."""
    r = min(rmax, 1.0 / grid.inv_h)
    n = _nearest(lp, grid, prm, x, medium, r, m, state, knn, kd, kv, buf)
    while n < knn and r < rmax:
        r = min(2.0 * r, rmax)
        n = _nearest(lp, grid, prm, x, medium, r, m, state, knn, kd, kv, buf)
    rk = math.sqrt(kd[n - 1]) if n == knn else rmax
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    for i in range(n):
        v = kv[i]
        ph = hg_eval(g, d_cam[0] * lp.d_in[v, 0] + d_cam[1] * lp.d_in[v, 1] + d_cam[2] * lp.d_in[v, 2])
        a0 += ph * lp.beta[v, 0]
        a1 += ph * lp.beta[v, 1]
        a2 += ph * lp.beta[v, 2]
    return (a0, a1, a2), n, rk


@block
def beam_weight(beams, b):
    """The selection weight of camera beam ``b``: the max component of its camera weight."""
    return max(beams[b, BEAM_W], beams[b, BEAM_W + 1], beams[b, BEAM_W + 2])


@block
def _pick_beam(beams, nb, u):
    """A beam with probability proportional to :func:`beam_weight`; (b, P(b))."""
    tot = 0.0
    for b in range(nb):
        tot += beam_weight(beams, b)
    if not tot > 0.0:
        return -1, 0.0
    x = u * tot
    for b in range(nb):
        w = beam_weight(beams, b)
        if x < w or b == nb - 1:
            return b, w / tot
        x -= w
    return -1, 0.0


@block
def vpm_beam(media, lp, grid, prm, h, beams, bstate, nb, r, K, knn, kd, kv, buf):
    """VPM along the camera path's beams (module docstring): (camera weight x T / pdf x
    sum rho beta averaged over the K samples -- the kernel's 1 / V(r) left to the caller, photon count).
    ``media`` holds the medium rows (``sa.media``), ``beams`` / ``bstate`` the path's nb beams.
    ``knn`` > 0: each sample's radius is its k-NN radius (``knn_point``, at most r; kd, kv its
    scratch of knn entries) and the sum carries its own 1 / V(r_k). ``buf``: the grid's candidates."""
    a = (0.0, 0.0, 0.0)
    cnt = 0
    for k in range(K):
        b, pb = _pick_beam(beams, nb, rand_at(h, D_VOL + 2 * k))
        if b < 0:
            break
        med = int(beams[b, BEAM_MED])
        sig, alb, g = medium_params(media[med])
        sbar = (sig[0] + sig[1] + sig[2]) / 3.0
        s = beams[b, BEAM_S]
        if not sbar > 0.0:          # sigma_t = 0: no collision, no in-scattering
            continue
        t, pdf = sample_distance_truncated_1(sbar, s, (k + rand_at(h, D_VOL + 2 * k + 1)) / K)
        if not pdf > 0.0:
            continue
        o = (beams[b, BEAM_O], beams[b, BEAM_O + 1], beams[b, BEAM_O + 2])
        d = (beams[b, BEAM_D], beams[b, BEAM_D + 1], beams[b, BEAM_D + 2])
        x = (o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2])
        if knn > 0:
            phi, c, rk = knn_point(lp, grid, prm, x, d, med, g, knn, r, int(bstate[b, 1]), bstate[b, 0], kd, kv,
                                   buf)
            iv = 1.0 / ball_volume(rk)
            phi = (phi[0] * iv, phi[1] * iv, phi[2] * iv)
        else:
            phi, c = vpm_point(lp, grid, prm, x, d, med, g, r, int(bstate[b, 1]), bstate[b, 0], buf)
        cnt += c
        tr = transmittance(sig, t)
        k0 = 1.0 / (pdf * pb * K)
        a = (a[0] + beams[b, BEAM_W] * tr[0] * phi[0] * k0, a[1] + beams[b, BEAM_W + 1] * tr[1] * phi[1] * k0,
             a[2] + beams[b, BEAM_W + 2] * tr[2] * phi[2] * k0)
    return a, cnt


@inlined
def beam_kernel(kernel, r, s, tp, dp2, h, b, v):
    """The BRE's kernel for photon row v at distance ``tp`` along camera beam b (length s, random
    stream h) and squared distance ``dp2`` from it: ``(ok, t, kw)``, t the point on the beam the
    photon scatters towards and kw its kernel weight. 2D: Jarosz et al. 2008's biweight disc facing
    the ray, t = tp. 3D: a ball of radius r, t uniform on the chord the beam cuts through it (the
    random number keyed by (beam, photon), so a gradient estimator's base sees the same t), kw the
    ball's kernel over the chord density 1 / (2 half). ok is False outside the kernel or the beam."""
    if kernel == KERNEL_2D:
        if not (dp2 < r * r and 0.0 < tp < s):
            return False, 0.0, 0.0
        return True, tp, biweight(dp2 / (r * r)) / (r * r)
    if not dp2 < r * r:
        return False, 0.0, 0.0
    half = math.sqrt(r * r - dp2)
    t = tp + (2.0 * rand_at(h, D_CHORD + (b << 32) + v) - 1.0) * half
    if not (0.0 < t < s):
        return False, 0.0, 0.0
    return True, t, 2.0 * half / ball_volume(r)


@block
def bre_beam(media, lp, bbh, radius, prm, h, beams, bstate, b, kernel, buf):
    """The beam radiance estimate along beam b (module docstring): (camera weight x sum of photon
    terms, photons counted). ``radius`` is indexed by light-vertex row; ``buf`` holds candidates."""
    med = int(beams[b, BEAM_MED])
    sig, alb, g = medium_params(media[med])
    o = np.empty(3)
    d = np.empty(3)
    for c in range(3):
        o[c] = beams[b, BEAM_O + c]
        d[c] = beams[b, BEAM_D + c]
    s = beams[b, BEAM_S]
    m = int(bstate[b, 1])
    state = bstate[b, 0]
    n = bbh_mod.collect(bbh, o, d, s, kernel, buf)
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    cnt = 0
    for i in range(min(n, buf.shape[0])):
        v = buf[i]
        if not _admit(lp, v, prm, med, m, state):
            continue
        r = radius[v]
        qx = lp.pos[v, 0] - o[0]
        qy = lp.pos[v, 1] - o[1]
        qz = lp.pos[v, 2] - o[2]
        tp = qx * d[0] + qy * d[1] + qz * d[2]
        qx -= tp * d[0]
        qy -= tp * d[1]
        qz -= tp * d[2]
        dp2 = qx * qx + qy * qy + qz * qz
        ok, t, kw = beam_kernel(kernel, r, s, tp, dp2, h, b, v)
        if not ok:
            continue
        cnt += 1
        tr = transmittance(sig, t)
        ph = hg_eval(g, dot((d[0], d[1], d[2]), (lp.d_in[v, 0], lp.d_in[v, 1], lp.d_in[v, 2]))) * kw
        a0 += ph * tr[0] * lp.beta[v, 0]
        a1 += ph * tr[1] * lp.beta[v, 1]
        a2 += ph * tr[2] * lp.beta[v, 2]
    return (beams[b, BEAM_W] * a0, beams[b, BEAM_W + 1] * a1, beams[b, BEAM_W + 2] * a2), cnt
