"""The camera pass of gradient-domain photon mapping (Hua et al. 2017, Sec. 4; PHOTONS.md Sec. 2).

Every pixel's gather point (the SPPM gather of :mod:`gdlearn.integrators.photon.gather`) is
shifted to its four neighbours, and every photon it gathers follows by the hybrid shift:

1. **Sensor subpath**: the gather path is re-traced from the neighbour's film position (the base
   position +-1 pixel, so the sub-pixel offset is kept) with the base path's random numbers -- the
   random-sequence replay shift, whose path-space Jacobian is p(z) / p(z') (Kettunen et al. 2015;
   :mod:`gdlearn.shifts.replay`): the offset's camera weight is its own f / p and the camera
   side contributes 1 to the MIS ratio. On a gather point seen directly, and through delta
   mirrors, this is the paper's half-vector copy (the direction law is the same); the shift is
   refused when the offset's chain differs from the base's in length or in the classes of its
   vertices (a symmetric test, so the two-way weights still sum to one).
2. **Offset photon**: Eq. 5 (copy in the tangent frames) and the projection from the photon's
   parent, Eq. 6 (:mod:`gdlearn.shifts.photon`).
3. **Light subpath** (:mod:`gdlearn.integrators.photon.gpm_light`): reconnection y_{s-1} -> y'_s
   when the parent is diffuse or glossy above the threshold, or the emitter (area, point, spot);
   the manifold walk (Eq. 7-8) when the parent lies on a chain of delta vertices on analytic shapes
   (spheres, rectangles). Glossy chains (Eq. 9-10) and chains the walk cannot move *fail*
   (weight 1, zero offset, counted), which keeps the gradient unbiased and makes it the primal
   finite difference for those photons.

Organisation (for speed; benchmarks/README.md, GPM section): the per-photon loop is
:mod:`gdlearn.integrators.photon.photon_shift_loop`'s, shared with the surface part of the volumetric
full images: the pixel's nine photon buffers and its shift counts are summed in a row scratch term by
term in photon order and written once -- the same additions in the same order as one write per term,
so every buffer is bit for bit that of the straightforward kernel (tests/_gpm_reference.py, whose
buffers tests/golden/passes.py records and tests/test_photon_fast_passes.py compares); a photon's parent is
re-evaluated towards the base direction once for its four shifts (:func:`photon_base`:
``gpm_light.parent_base``), each shift evaluating only the offset direction (``parent_offset``);
the shift, its projection and its reversibility check are inlined into the photon loop.

The offset photon must lie within the base gather point's radius of the offset gather point
(PHOTONS.md Sec. 2.6); the density query is made only around the base gather point (Sec. 1.4).
The MIS weight is Eq. 11 in ratio form (:func:`gdlearn.shifts.mis.mis_weight_from_log_ratio`) in
both branches of the light subpath.

Buffers (the contract of :mod:`gdlearn.integrators.gradients`), per half and base pixel: ``L``
(index 0), ``D_k`` (1 + k) and ``S_k`` (5 + k), k = right, left, down, up, each once for the photon
density terms (``phi``, to be divided by pi r^2 and the light paths emitted) and once for the
emission the camera paths see (``le``: replayed camera paths, balance weight 1/2).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit_inline
from gdlearn.kernels.arrays import borrow, borrowed
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import offset_origin
from gdlearn.kernels.jit import block, inlined
from gdlearn.kernels.threads import next_rows, run_rows
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.photons import grid as hashgrid
from gdlearn.photons.trace import _borrow_rec
from gdlearn.integrators.photon.gather import _borrow_grid, gather_path, pixel_angle
from gdlearn.integrators.photon.gpm_light import P_FAIL, _dir, parent_base, parent_offset, project, same_point
from gdlearn.integrators.photon.photon_manifold import manifold_photon
from gdlearn.integrators.photon.photon_shift_loop import FAILED, MANIFOLD, RECONNECTED, at_offset, finite3, \
    make_shift_photons, offset_points, put, store_offset
from gdlearn.shifts.photon import offset_target, photon_geometry_ratio, rotate
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY


class GpmOut(NamedTuple):
    phi: np.ndarray       # (2, 9, H, W, 3): L, D_k, S_k of the photon terms (camera weight included)
    le: np.ndarray        # (2, 9, H, W, 3): the same for the emission seen by the camera paths
    m: np.ndarray         # (2, H, W): photons found by the base gather point (SPPM's M)
    foot: np.ndarray      # (2, H, W): pixel footprint at the base gather point (0: none)
    count: np.ndarray     # (2, 3, H, W): photon shifts reconnected / failed / moved by the manifold walk
    bad: np.ndarray       # (H,): non-finite terms dropped


def allocate(h: int, w: int) -> GpmOut:
    return GpmOut(np.zeros((2, 9, h, w, 3)), np.zeros((2, 9, h, w, 3)), np.zeros((2, h, w)), np.zeros((2, h, w)),
                  np.zeros((2, 3, h, w)), np.zeros(h, np.int64))


@block
def shift_photon(sa, lp, mtab, prm, v, base, off, r, stack):
    """The hybrid shift's light half for photon row ``v`` gathered at ``base`` = (p, frame) and
    moved to the offset gather point ``off`` = (p', ng', frame', wi', mat'). Returns (status,
    photon term at the offset (before the camera weight), MIS density ratio offset / base)."""
    return _shift(sa, lp, mtab, prm, v, photon_base(sa, lp, v, r, stack), base, off, r, stack)


@inlined
def photon_base(sa, lp, v, r, stack):
    """Photon row v's base side, the same for its four shifts (photon_shift_loop's contract): its
    parent row q and the parent re-evaluated towards the base direction (``gpm_light.parent_base``,
    Hua et al. 2017 Sec. 4.2 Step 2; P_FAIL without a parent)."""
    q = lp.parent[v]
    if q < 0:
        return q, (P_FAIL, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 0.0)
    return q, parent_base(sa, lp, q, v)


@inlined
def _shift(sa, lp, mtab, prm, v, pb, base, off, r, stack):
    """:func:`shift_photon` from the photon's base side ``pb`` = (q, parent_base) (:func:`photon_base`,
    computed once per photon for the four neighbours). Inlined into the photon loop: a call passing
    the scene, the light records and the two gather points as tuples costs about as much as the
    shift's arithmetic."""
    zero = (0.0, 0.0, 0.0)
    q, pbase = pb
    if q < 0:
        return FAILED, zero, 0.0
    p, frame = base
    p2, ng2, frame2, wi2, mat2 = off
    ys = (lp.pos[v, 0], lp.pos[v, 1], lp.pos[v, 2])
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    ystar = offset_target(ys, p, frame, p2, frame2)                        # Eq. 5
    # y* lies on the photon's tangent plane carried by the rigid map of Eq. 5: its normal is the
    # photon's, rotated (the offset gather point's normal, the reference code's choice, is the same
    # for a photon on the gather point's own plane and wrong for one on a neighbouring surface)
    nv = (lp.nrm[v, 0], lp.nrm[v, 1], lp.nrm[v, 2])
    nstar = rotate(nv, frame, frame2)
    d, dl = _dir(yq, ystar)
    if not dl > 0.0:
        return FAILED, zero, 0.0
    status, fr, pr = parent_offset(sa, lp, q, pbase, d)
    if status == 2:                                                        # a specular parent
        ok, ratio3, pp, w_arr = manifold_photon(sa, lp, mtab, prm, v, q, ystar, nstar, r, p2, stack)
        return at_offset(MANIFOLD if ok else FAILED, lp, v, ratio3, pp, w_arr, off)
    if status != 0:
        return FAILED, zero, 0.0
    ok, _, yh, _ = project(sa, prm, yq, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), ystar, p2, r, stack)   # Eq. 6
    if not (ok and _reversible(sa, lp, q, ys, yh, ystar, p, frame, p2, frame2, r, stack)):
        return FAILED, zero, 0.0
    geo = photon_geometry_ratio(yq, ys, nv, ystar, nstar)
    if not geo > 0.0:
        return FAILED, zero, 0.0
    return at_offset(RECONNECTED, lp, v, (fr[0] * geo, fr[1] * geo, fr[2] * geo), pr * geo, d, off)


@inlined
def _reversible(sa, lp, q, ys, yh, ystar, p, frame, p2, frame2, r, stack):
    """Does the inverse shift take the offset photon y'_s back to y_s (Hua et al. 2017 Sec. 4.3)?
    When the projection did not move y* (y'_s = y*_s, a photon on a plane the shift slides along)
    Eq. 5 inverts exactly; otherwise the inverse target is projected from the parent and must land
    on y_s. Without this the two MIS weights of a path pair need not sum to one (a photon near a
    corner, whose y* falls off its surface, projects onto the next one)."""
    yq = (lp.pos[q, 0], lp.pos[q, 1], lp.pos[q, 2])
    if same_point(yh, ystar, yq, r):
        return True
    d, dl = _dir(yq, offset_target(yh, p2, frame2, p, frame))
    if not dl > 0.0:
        return False
    o = offset_origin(yq, (lp.nrm[q, 0], lp.nrm[q, 1], lp.nrm[q, 2]), d)
    t, prim, u, w = closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, math.inf, stack)
    return prim >= 0 and same_point((o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]), ys, yq, r)


#: the per-photon loop (photon_shift_loop) with GPM's surface shift
_shift_photons = make_shift_photons(photon_base, _shift)


def gpm_rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out):
    """Every pixel's two base gather points (samples sample0 + h, half h queries grids[h]) and their
    four shifts into ``out`` (a :class:`GpmOut`); ``radius`` (H x W) is the kernel radius per pixel;
    ``mtab`` the manifold shape rows of the primitives (the manifold branch's chains). The rows run
    on threads (``kernels.threads.run_rows``): no parallel kernel to compile."""
    _gpm_pass(sa, lp, grids, mtab, prm, seed, sample0, radius, out)


@block
def borrow_out(o):
    """A :class:`GpmOut` of borrowed views (kernels.arrays.borrow) for a compiled pass."""
    return GpmOut(borrow(o.phi), borrow(o.le), borrow(o.m), borrow(o.foot), borrow(o.count), borrow(o.bad))


def threaded_rows(row):
    """A camera pass with GPM's arguments over the whole image, its rows on threads in chunks
    (``kernels.threads.run_rows``): ``row(sa, lp, grids, mtab, prm, seed, sample0, radius, out, y)``
    renders row y into ``out`` (a :class:`GpmOut`) and returns the non-finite terms it dropped; the
    returned ``rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out)`` runs it over every row.
    GPM's pass and the surface pass of G-VPM's and G-BRE's full images
    (``gvol_surface.surface_rows``) share it; a ``row`` declared ``ir_inline`` is inlined into the
    threads' driver (numba inlines a closure's compiled function as it does a global)."""

    @block(nogil=True)
    def each_row(sa, lp, ga, gb, mtab, prm, seed, sample0, radius, out, counter, step):
        """One thread's share: chunks of ``step`` rows taken from ``counter``."""
        # borrowed views: no atomic reference counts shared by the threads (kernels.arrays.borrow)
        sb, lb, grids, mb, ob = borrowed(sa), _borrow_rec(lp), (_borrow_grid(ga), _borrow_grid(gb)), borrow(mtab), \
            borrow_out(out)
        h = radius.shape[0]
        while True:
            y0, y1 = next_rows(counter, step, h)
            if y0 == y1:
                return
            for y in range(y0, y1):
                ob.bad[y] = row(sb, lb, grids, mb, prm, seed, sample0, radius, ob, y)

    def rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out):
        run_rows(lambda counter, step: each_row(sa, lp, grids[0], grids[1], mtab, prm, seed, sample0, radius, out,
                                                counter, step), radius.shape[0])

    return rows


@block
def _gpm_row(sa, lp, grids, mtab, prm, seed, sample0, radius, out, y):
    hgt, w = radius.shape
    cam = sa.camera
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    cand = np.empty(4096, dtype=np.int64)
    offs = offset_points()          # the four offset gather points of the current base sample
    o_ok = offs[0]
    acc = np.empty((9, 3))          # the pixel's nine buffers while its photons are summed (_shift_photons)
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, tmax = camera_ray(cam, fx, fy)
            ok, p, ng, frame, wi, mid, beta, state, m, dist, le = gather_path(sa, prm, h, o, d, stack)
            if finite3(le):
                put(out.le, hh, 0, y, x, le, 1.0)
            for k in range(4):
                o_ok[k] = False
                xo, yo = x + SHIFT_DX[k], y + SHIFT_DY[k]
                if not (0 <= xo < w and 0 <= yo < hgt):
                    if finite3(le):
                        put(out.le, hh, 1 + k, y, x, le, -1.0)      # a shift outside the image fails
                    continue
                o2, d2, _ = camera_ray(cam, fx + SHIFT_DX[k], fy + SHIFT_DY[k])
                ok2, p2, ng2, fr2, wi2, mid2, beta2, state2, m2, _, le2 = gather_path(sa, prm, h, o2, d2, stack)
                if finite3(le) and finite3(le2):                   # replayed camera paths: w = 1/2 each way
                    put(out.le, hh, 1 + k, y, x, (le2[0] - le[0], le2[1] - le[1], le2[2] - le[2]), 0.5)
                    put(out.le, hh, 5 + k, y, x, le2, 0.5)
                if ok and ok2 and m2 == m and state2 == state:
                    store_offset(offs, k, p2, ng2, fr2, wi2, mid2, beta2)
            if not ok:
                continue
            out.foot[hh, y, x] = dist * pixel_angle(cam, fx, fy, d)
            r = radius[y, x]
            if not r > 0.0:
                continue
            n = hashgrid.query(grids[hh], p, r, cand)
            if n > cand.shape[0]:
                cand = np.empty(2 * n, dtype=np.int64)
                n = hashgrid.query(grids[hh], p, r, cand)
            nbad += _shift_photons(sa, lp, mtab, prm, out, hh, y, x, (p, ng, frame, wi, mid, beta, state, m), r, cand, n,
                                   offs, acc, stack)
    return nbad


_gpm_pass = threaded_rows(_gpm_row)
