"""Reversibility of gpt's surface shifts, vertex by vertex: T^{-1}(T(x)) = x (STAR Sec. 3.5, Fig. 4).

Eq. 17's weights of a forward and a backward shift sum to one only on pairs the backward shift maps
back. Here the kernels' own shift steps (``gpt_path._shift_segment`` for Kettunen et al.'s policy,
``gpt_mixed.shift_segment_mixed`` for the mixed ones) shift many sampled base paths x one pixel to
the right, step by step as gpt does; every step that did not fail is recorded as the offset path y.
Then y is taken as the base path of the right-hand pixel and shifted back to the left with the same
functions. The data the backward steps need from y are all functions of y -- its vertices, its
directions, their densities and lobe kinds -- except the random numbers at the vertices the forward
shift *replayed*, which are x's by definition of replay. The backward offset must reproduce x's
vertices, and reconnect exactly where the forward shift did (after a reconnection both paths share
every vertex).

A pair that the forward shift declared failed proves nothing and is skipped; the broken variant
(``BROKEN_REVERSIBILITY``: no check after a step that did not reconnect) must produce violations, so
the test can fail. So does a short-segment guard (``reconnection.far_enough``) left out of the
forward decision but kept in the check: 177-235 violations per case (measured when the guard came
to the surface kernels). Seeds are fixed; nothing here is statistical (positions agree to rounding: the
tolerance 1e-6 is ~1e-6 of the scene size, the differences seen are ~1e-12).
"""
import copy
import math

import numpy as np
import pytest
from numba import njit

from gdlearn.integrators import make
from gdlearn.integrators.path.params import VB_SURFACE, BaseVertex, GptParams, NextVertex, Pixel
from gdlearn.integrators.path.gpt_volume.flight import EV_ESCAPE, EV_SURFACE
from gdlearn.kernels.bsdf.dispatch import bsdf_sample, lobe_class, sampled_lobe_class
from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import offset_origin
from gdlearn.integrators.path.gpt_surface.mixed import shift_segment_mixed
from gdlearn.integrators.path.gpt_surface.lockstep import _shift_segment, _start_offsets, cls_next_of
from gdlearn.integrators.path.gpt_surface.vertex import (ALIVE, BROKEN_LOBE_CLASS, BROKEN_REVERSIBILITY, F_NG, F_NS, F_POS,
                                       F_PREV_PDF, F_WI, I_ALIVE, I_ESCAPED, I_MAT, I_PREV_DELTA, I_PRIM, I_RECONN,
                                       JOINED, NF, NI, get3)
from gdlearn.kernels.rng import rand
from gdlearn.kernels.scene_query import intersect
from gdlearn.integrators.path.surface import D_BSDF_U1, D_BSDF_U2, D_LOBE, dim
from gdlearn.kernels.vec import coordinate_system, to_local, to_world
from gdlearn.scene.load import load
from gdlearn.shifts.policy import N_STATS, is_mixed, policy_code
from gdlearn.shifts.replay import offset_film_position

ROOT = __file__.rsplit("/tests/", 1)[0]
MAXV = 10
TOL = 1e-6
# per-vertex float record: position, ng, ns, then the segment leaving it: local wi, local wo, pdf,
# delta (0/1), decision class, u_lobe, u1, u2
R_P, R_NG, R_NS, R_WI, R_WO, R_PDF, R_DELTA, R_CLS, R_U = 0, 3, 6, 9, 12, 15, 16, 17, 18
NR = 21
# per-vertex int record: hit (0 escaped / 1), prim, material
NRI = 3


@njit(cache=True)
def _trace_base(sa, fx, fy, seed, key, s, max_v, threshold, broken, rec, irec, stack):
    """Sample a base path (BSDF sampling only: the shift map does not depend on next-event samples or
    roulette) into rec / irec; vertex 0 is the camera. Returns the number of vertices after the camera."""
    o, d, tmax = camera_ray(sa.camera, fx, fy)
    hit, _, prim, p, ng, ns, _ = intersect(sa, o, d, 0.0, tmax, stack)
    n = 0
    while True:
        n += 1
        for c in range(3):
            rec[n, R_P + c], rec[n, R_NG + c], rec[n, R_NS + c] = p[c], ng[c], ns[c]
        irec[n, 0], irec[n, 1] = (1 if hit else 0), prim
        if not hit or n >= max_v:
            return n
        mat = sa.materials[sa.prim_info[prim, 1]]
        irec[n, 2] = sa.prim_info[prim, 1]
        sf, tf = coordinate_system(ns)
        wi = to_local((-d[0], -d[1], -d[2]), sf, tf, ns)
        u = (rand(seed, key, s, dim(n - 1, D_LOBE)), rand(seed, key, s, dim(n - 1, D_BSDF_U1)),
             rand(seed, key, s, dim(n - 1, D_BSDF_U2)))
        wo, _, pdf, delta = bsdf_sample(mat, wi, u[0], u[1], u[2])
        if not pdf > 0.0:
            return n
        cls = sampled_lobe_class(mat, wi, u[0], delta, threshold) if broken == BROKEN_LOBE_CLASS else \
            lobe_class(mat, delta, threshold)
        for c in range(3):
            rec[n, R_WI + c], rec[n, R_WO + c], rec[n, R_U + c] = wi[c], wo[c], u[c]
        rec[n, R_PDF], rec[n, R_DELTA], rec[n, R_CLS] = pdf, 1.0 if delta else 0.0, cls
        d = to_world(wo, sf, tf, ns)
        hit, _, prim, p, ng, ns, _ = intersect(sa, offset_origin(p, ng, d), d, 0.0, math.inf, stack)


@njit(cache=True)
def _store(of, oi, k, j, out, iout):
    for c in range(3):
        out[j, R_P + c], out[j, R_NG + c], out[j, R_NS + c] = of[k, F_POS + c], of[k, F_NG + c], of[k, F_NS + c]
    iout[j, 0], iout[j, 1], iout[j, 2] = 1 - oi[k, I_ESCAPED], oi[k, I_PRIM], oi[k, I_MAT]


@njit(cache=True)
def _shift(sa, cfg, fx, fy, x, w, h, k, n, rec, irec, out, iout, stack):
    """Shift the recorded base path (n vertices) to neighbour k with gpt's steps and record the offset
    path in out / iout like the base (its random numbers: the base's). Returns ``(m, joined_at,
    failed)``: m vertices recorded, the step whose reconnection joined the base (-1: none). ``cfg``: the
    kernels' :class:`~gdlearn.integrators.path.params.GptParams`."""
    policy, threshold = cfg.policy, cfg.threshold
    of = np.zeros((4, NF))
    oi = np.zeros((4, NI), dtype=np.int64)
    stats = np.zeros(N_STATS, dtype=np.int64)
    _start_offsets(sa, Pixel(fx, fy, x, 0, w, h), of, oi, stack)
    _store(of, oi, k, 1, out, iout)
    for j in range(1, n):
        if oi[k, I_ESCAPED] == 1 or irec[j, 0] == 0:
            return j, -1, False
        ns_o = get3(of, k, F_NS)
        so, to = coordinate_system(ns_o)
        wi_o = to_local(get3(of, k, F_WI), so, to, ns_o)
        mat_b = sa.materials[irec[j, 2]]
        p, ng = (rec[j, 0], rec[j, 1], rec[j, 2]), (rec[j, 3], rec[j, 4], rec[j, 5])
        wi, wo = (rec[j, 9], rec[j, 10], rec[j, 11]), (rec[j, 12], rec[j, 13], rec[j, 14])
        us = (rec[j, 18], rec[j, 19], rec[j, 20])
        hit2, prim2 = irec[j + 1, 0] == 1, irec[j + 1, 1]
        p2, ng2 = (rec[j + 1, 0], rec[j + 1, 1], rec[j + 1, 2]), (rec[j + 1, 3], rec[j + 1, 4], rec[j + 1, 5])
        ns2 = (rec[j + 1, 6], rec[j + 1, 7], rec[j + 1, 8])
        d2 = (p2[0] - p[0], p2[1] - p[1], p2[2] - p[2])
        cls, delta, pdf = int(rec[j, R_CLS]), rec[j, R_DELTA] > 0.5, rec[j, R_PDF]
        ns = (rec[j, 6], rec[j, 7], rec[j, 8])
        # the recorded base vertex x_j and its next vertex x_{j+1}, as the kernels bundle them
        bv = BaseVertex(VB_SURFACE, p, ng, ns, irec[j, 1], -1, mat_b, wi, wo, d2, (1.0, 1.0, 1.0), pdf, delta, cls,
                        cls, us)
        nx = NextVertex(hit2, EV_SURFACE if hit2 else EV_ESCAPE, prim2, p2, ng2, ns2, d2, -1,
                        cls_next_of(sa, hit2, prim2, cfg), False)
        if is_mixed(policy):
            shift_segment_mixed(sa, k, of, oi, cfg, bv, nx, stats, stack)
        else:
            _shift_segment(sa, k, of, oi, cfg, bv, nx, stats, stack)
        if oi[k, I_ALIVE] != ALIVE:
            return j, -1, True
        # the offset's segment leaving its vertex j: directions in its own frame, density, lobe kind
        wo_o = to_local((-of[k, F_WI], -of[k, F_WI + 1], -of[k, F_WI + 2]), so, to, ns_o)
        dl = oi[k, I_PREV_DELTA] == 1
        for c in range(3):
            out[j, R_WI + c], out[j, R_WO + c], out[j, R_U + c] = wi_o[c], wo_o[c], us[c]
        out[j, R_PDF], out[j, R_DELTA] = of[k, F_PREV_PDF], 1.0 if dl else 0.0
        out[j, R_CLS] = lobe_class(sa.materials[iout[j, 2]], dl, threshold)
        _store(of, oi, k, j + 1, out, iout)
        if oi[k, I_RECONN] == JOINED:
            return j + 1, j, False
    return n, -1, False


def _scene(name, res):
    """A scene file, or the caustics box with rough interfaces (``near-specular``: below the roughness
    threshold, half-vector copies; ``glossy``: connectable) or a rough-plastic floor below the
    threshold (``roughplastic``: coating lobe specular-class, base lobe diffuse)."""
    if name in ("near-specular", "glossy"):
        sc = load(f"{ROOT}/scenes/caustics-box.xml", res=res)
        for shape in sc.shapes:
            if shape.bsdf.type in ("conductor", "dielectric"):
                shape.bsdf = copy.copy(shape.bsdf)
                shape.bsdf.alpha = {"near-specular": 0.02, "glossy": 0.3}[name]
                shape.bsdf.type = "rough" + shape.bsdf.type
        return sc
    if name == "roughplastic":
        sc = load(f"{ROOT}/scenes/caustics-box.xml", res=res)
        for shape in sc.shapes:
            if shape.id == "floor":
                shape.bsdf = copy.copy(shape.bsdf)
                shape.bsdf.type, shape.bsdf.alpha, shape.bsdf.distribution = "roughplastic", 0.02, "ggx"
        return sc
    return load(f"{ROOT}/scenes/{name}.xml", res=res)


def check(scene_name, policy, broken=0, res=16, spp=16, seed=5):
    """Forward and backward shifts of res^2 * spp base paths (rightward); returns counters."""
    integ = make("pt", _scene(scene_name, res))
    sa, th, code = integ.setup.sa, integ.setup.threshold, policy_code(policy)
    w = h = res
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    rec, irec = np.zeros((MAXV + 1, NR)), np.zeros((MAXV + 1, NRI), dtype=np.int64)
    off, ioff = np.zeros((MAXV + 1, NR)), np.zeros((MAXV + 1, NRI), dtype=np.int64)
    back, iback = np.zeros((MAXV + 1, NR)), np.zeros((MAXV + 1, NRI), dtype=np.int64)
    c = {"checked": 0, "failed_forward": 0, "violations": 0, "joined": 0, "continued": 0}
    for y in range(h):
        for x in range(w - 1):
            key = y * w + x
            for s in range(spp):
                fx, fy = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
                n = _trace_base(sa, fx, fy, seed, key, s, MAXV, th, broken, rec, irec, stack)
                m, joined, failed = _shift(sa, GptParams(code, 0, 0, 0, th, broken), fx, fy, x, w, h, 0, n, rec, irec, off, ioff, stack)
                if failed:
                    c["failed_forward"] += 1
                    continue
                ox, oy = offset_film_position(fx, fy, 0)
                mb, joined_b, failed_b = _shift(sa, GptParams(code, 0, 0, 0, th, 0), ox, oy, x + 1, w, h, 1, m, off, ioff, back, iback,
                                                stack)
                c["checked"] += 1
                c["joined"] += joined >= 0
                c["continued"] += joined > 1 or (joined < 0 and m > 1)   # a step that did not reconnect
                ok = not failed_b and joined_b == joined and mb == m
                ok = ok and np.array_equal(iback[1:m + 1, 0], irec[1:m + 1, 0])
                hit = irec[1:m + 1, 0] == 1
                ok = ok and np.allclose(back[1:m + 1, :3][hit], rec[1:m + 1, :3][hit], atol=TOL, rtol=0.0)
                c["violations"] += not ok
    return c


@pytest.mark.parametrize("scene_name,policy", [("caustics-box", "replay+reconnection"),
                                               ("caustics-box", "halfvector+replay+reconnection"),
                                               ("caustics-box", "halfvector+reconnection"),
                                               ("near-specular", "halfvector+replay+reconnection"),
                                               ("near-specular", "halfvector+reconnection"),
                                               ("glossy", "replay+reconnection"),
                                               ("roughplastic", "replay+reconnection"),
                                               ("cornell-box", "replay+reconnection")])
def test_backward_shift_returns_the_base_path(scene_name, policy):
    c = check(scene_name, policy)
    # enough non-trivial pairs: many reconnected, many continued (replay, half-vector copy) first
    assert c["checked"] > 2000 and c["joined"] > 500 and c["continued"] > 200, c
    assert c["violations"] == 0, f"{policy} on {scene_name}: T^-1(T(x)) != x on {c['violations']} pairs: {c}"


@pytest.mark.parametrize("scene_name,policy,broken", [("caustics-box", "replay+reconnection", BROKEN_REVERSIBILITY),
                                                      ("caustics-box", "halfvector+reconnection", BROKEN_REVERSIBILITY),
                                                      ("roughplastic", "replay+reconnection", BROKEN_LOBE_CLASS)])
def test_broken_variants_are_caught(scene_name, policy, broken):
    """Without the reversibility check (a replayed offset whose backward shift would reconnect keeps
    its weight), or with decisions that read a rough plastic's random lobe choice, the backward shift
    must miss some base paths."""
    c = check(scene_name, policy, broken=broken)
    assert c["violations"] > 10, c
