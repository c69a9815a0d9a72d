"""The surface part of a gradient-domain volumetric full image (G-VPM's, and G-BRE's to come): GPM's
gradients (Hua et al. 2017) at gather points reached through participating media (Gruson et al.
2018, Sec. 6: "surface interactions are handled by [Hua et al. 2017]"; PHOTONS.md Sec. 0.2 and 5.5).

A volumetric integrator runs this pass beside its medium pass; both write the buffers of
:mod:`gdlearn.integrators.gradients` -- per half and base pixel L (index 0), D_k (1 + k), S_k (5 + k),
k = right, left, down, up -- with one MIS convention: the balance heuristic in ratio form
(:func:`gdlearn.shifts.mis.mis_weight_from_log_ratio`) inside D_k and S_k, a failed shift (or a
neighbour outside the image, PHOTONS.md E12) weight 1 and no offset. The output is GPM's
:class:`gdlearn.integrators.photon.gpm_gather.GpmOut`: ``phi`` to be divided by pi r^2 and the
light paths emitted (the caller's statistics: per-pixel R, N for G-VPM, a global schedule for
G-BRE), ``le`` the emission the camera paths see.

Per pixel and half (camera sample sample0 + hh, the sample VPM's surface gather uses, so the base
buffer *is* VPM's surface estimate and emission, :mod:`gdlearn.integrators.photon.volume_gather`):

1. **Camera subpath** (:func:`gdlearn.integrators.photon.camera_beams.beam_path`): through media
   with long beams (no collision is sampled, the weight takes T of every segment) and specular
   vertices to the first non-specular surface, the gather point.
2. **Offset camera subpath**: the *same* shift as the medium part's
   (:mod:`gdlearn.integrators.photon.gvpm_gather`) and as GPM's: the path re-traced from the
   neighbour's film position with the base's random numbers (random replay; at delta vertices this
   is the half-vector copy of Hua et al. 2017, Sec. 4.2 Step 1, the direction law being the same;
   PHOTONS.md Sec. 2.3). Its camera weight is its own f / p -- the transmittance along the offset's
   own beams to the offset gather point included, since beam_path multiplies every segment's T into
   it -- and the camera side contributes 1 to the MIS ratio. The camera distance copy of Gruson et
   al. 2018 (Sec. 4.2, Eq. 14-15) does not apply: a path ending on a surface samples no distance on
   its beams, so there is nothing to copy. The shift fails unless the offset reaches a gather point
   after as many vertices of the same classes (GPM's symmetric rule; the beam structure the medium
   part requires is not needed here, where no beam is shifted).
3. **Photon shift**: GPM's hybrid shift with the light edge through media
   (:func:`gdlearn.integrators.photon.gvol_surface_light.shift_surface_photon`), in GPM's photon
   loop (:mod:`gdlearn.integrators.photon.photon_shift_loop`): the photon's parent, its base half
   and its recorded edge's media once per photon for the four neighbours, the pixel's buffers summed
   in a row scratch in photon order and written once (bit for bit the straightforward loop's,
   tests/test_photon_fast_passes.py).
4. **Emission** seen by the camera paths: the replayed pair, balance weight 1/2 each way (as GPM).
"""
from __future__ import annotations

import numpy as np

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.jit import block, ir_inline
from gdlearn.kernels.rng import path_state, rand_at
from gdlearn.photons import grid as hashgrid
from gdlearn.integrators.photon.camera_beams import BEAM_COLS, MAX_BEAMS, beam_path
from gdlearn.integrators.photon.gather import pixel_angle
from gdlearn.integrators.photon.gpm_gather import allocate, threaded_rows
from gdlearn.integrators.photon.gvol_surface_light import photon_base, shift_from_base
from gdlearn.integrators.photon.photon_shift_loop import FAILED, MANIFOLD, RECONNECTED, finite3, make_shift_photons, \
    offset_points, put, store_offset
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY

#: the images of the surface shift counts and their rows in GpmOut.count (gpm_gather's outcomes)
SURFACE_COUNTS = (("reconnected", RECONNECTED), ("manifold", MANIFOLD), ("failed", FAILED))


def surface_pass(setup, lp, grids, mtab, prm, seed, sample0, radius):
    """Run the pass over the image (radius: H x W kernel radii, 0 = no gather); a GpmOut."""
    out = allocate(*radius.shape)
    with setup.parallel(radius.shape[0]):
        surface_rows(setup.sa, lp, grids, mtab, prm, seed, sample0, radius, out)
    return out


#: the per-photon loop (photon_shift_loop: GPM's) with the shift through media and null interfaces
_shift_photons = make_shift_photons(photon_base, shift_from_base)


def surface_rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out):
    """Every pixel's two base gather points (half hh queries grids[hh]) and their four shifts. The
    rows run on threads (``kernels.threads.run_rows``) and the row is IR-inlined into their driver,
    for the cold compile (:func:`gdlearn.integrators.photon.gbre_gather.gbre_rows` says why), by GPM's
    driver (:func:`gdlearn.integrators.photon.gpm_gather.threaded_rows`)."""
    _surface_pass_rows(sa, lp, grids, mtab, prm, seed, sample0, radius, out)


@ir_inline
def _row(sa, lp, grids, mtab, prm, seed, sample0, radius, out, y):
    hgt, w = radius.shape
    cam = sa.camera
    nbad = 0
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    cand = np.empty(4096, dtype=np.int64)
    beams = np.empty((MAX_BEAMS, BEAM_COLS))
    bstate = np.empty((MAX_BEAMS, 2), dtype=np.int64)
    offs = offset_points()          # the four offset gather points of the current base sample
    acc = np.empty((9, 3))          # the pixel's nine buffers while its photons are summed (_shift_photons)
    for x in range(w):
        for hh in range(2):
            h = path_state(seed, y * w + x, sample0 + hh)
            fx = x + rand_at(h, 0)
            fy = y + rand_at(h, 1)
            o, d, _ = camera_ray(cam, fx, fy)
            ok, p, ng, frame, wi, mid, beta, state, m, dist, le, _ = beam_path(sa, prm, h, o, d, stack, beams, bstate)
            if finite3(le):
                put(out.le, hh, 0, y, x, le, 1.0)
            for k in range(4):
                _offset_path(sa, prm, h, fx, fy, x, y, w, hgt, k, stack, beams, bstate, (ok, state, m, le), offs,
                             out, hh)
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
            nbad += _shift_photons(sa, lp, mtab, prm, out, hh, y, x, (p, ng, frame, wi, mid, beta, state, m), r, cand,
                                   n, offs, acc, stack)
    return nbad


_surface_pass_rows = threaded_rows(_row)


@block
def _offset_path(sa, prm, h, fx, fy, x, y, w, hgt, k, stack, beams, bstate, base, offs, out, hh):
    """Neighbour k's replayed camera path: its emission pair into ``out.le`` and, if it reaches a gather
    point of the base's structure, that gather point into row k of ``offs`` (offs[0][k]: ok)."""
    ok, state, m, le = base
    offs[0][k] = False
    if not (0 <= x + SHIFT_DX[k] < w and 0 <= y + SHIFT_DY[k] < hgt):
        if finite3(le):
            put(out.le, hh, 1 + k, y, x, le, -1.0)          # a shift outside the image fails (E12)
        return
    o2, d2, _ = camera_ray(sa.camera, fx + SHIFT_DX[k], fy + SHIFT_DY[k])
    ok2, p2, ng2, fr2, wi2, mid2, beta2, state2, m2, _, le2, _ = beam_path(sa, prm, h, o2, d2, stack, beams, bstate)
    if finite3(le) and finite3(le2):                       # replayed camera paths: w = 1/2 each way
        put(out.le, hh, 1 + k, y, x, (le2[0] - le[0], le2[1] - le[1], le2[2] - le[2]), 0.5)
        put(out.le, hh, 5 + k, y, x, le2, 0.5)
    if ok and ok2 and m2 == m and state2 == state:
        store_offset(offs, k, p2, ng2, fr2, wi2, mid2, beta2)     # beta2: T of the offset's own beams inside
