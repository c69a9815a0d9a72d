"""Gradient-domain path tracing with shift mappings ("gpt"; Kettunen et al. 2015, STAR Sec. 3-4.1).

Every base path of pixel p (Mitsuba's ``path``, same kernels and random numbers as ``pt``) is shifted
to the four neighbours in lockstep by a combined shift policy (:mod:`gdlearn.shifts.policy`), and
each base / offset contribution pair is weighted by Eq. 17's balance heuristic
(:mod:`gdlearn.kernels.gpt_path` has the method). The accumulation layout is ``gpt-replay``'s: per
base pixel a primal buffer and four shift buffers (right, left, down, up), written by one row each,
combined afterwards into gx, gy -- with weights (1, 1) here, since the MIS weights are inside the
buffers (forward and backward weights of one path pair sum to one).

The primal image is Kettunen et al.'s MIS-weighted one (:func:`mis_primal`): each path pair also
estimates the pixel value twice, from the base path in p and from the offset path shifted back from
the neighbour, with the same Eq. 17 weights. ``images["primal"]`` is that estimate;
``images["primal_base"]`` is the base radiance alone (``pt``'s estimator, same random numbers).

Policies (``shift=``): ``replay`` (the whole path replayed, :mod:`gdlearn.kernels.gpt_replay_policy`:
``gpt-replay``'s estimator, Eq. 17 weights 1/2), the mixed policies ``replay+reconnection`` and
``halfvector+replay+reconnection`` (:mod:`gdlearn.kernels.gpt_mixed`: reconnect where the criterion
holds from both sides, else replay -- also through a class mismatch -- or copy the half vector between
two non-connectable vertices; fail only where the backward shift would reconnect),
``halfvector+reconnection`` (Kettunen et al.'s: fails on a class mismatch) and
``halfvector+reconnection+manifold`` (Kettunen et al.'s plus manifold exploration of specular chains
between connectable vertices, :mod:`gdlearn.kernels.gpt_manifold`). The manifold walk runs only where
the effects plan has specular chains and the scene has analytic specular shapes (``self.manifold``);
elsewhere that policy is halfvector+reconnection. Default (``shift=None``): :func:`default_policy` --
:data:`DEFAULT_RULE`, with the measurements in :data:`DEFAULT_POLICY`'s comment. Scenes with media or
null interfaces run the twin kernel :func:`gdlearn.kernels.gpt_volume.gpt_volume_rows` (same
signature and buffers), imported lazily; it has no manifold walk.

Frame stats: ``paths``, ``nonfinite_samples`` and, per shift action, ``shift_<action>_{run,ok,failed}``
(actions: replay, halfvector, reconnection, manifold, fail) counted over offset path segments.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit, prange

from ..kernels.bvh import STACK_SIZE
from ..kernels.gpt_path import gpt_sample
from ..kernels.gpt_manifold import NCF, NCI, manifold_table
from ..kernels.gpt_replay_policy import replay_sample
from ..kernels.gpt_shift import NF, NI
from ..kernels.gpt_volume import gpt_volume_rows
from ..kernels.rng import rand
from ..scene.compile import borrowed
from ..shifts.manifold import SH_WIDTH
from ..shifts.policy import (MAX_CHAIN, N_STATS, POLICIES, POLICY_HALFVECTOR_RECONNECTION, POLICY_REPLAY,
                             POLICY_HALFVECTOR_RECONNECTION_MANIFOLD, policy_code, stats_dict)
from ..shifts.replay import SHIFT_DX, SHIFT_DY, combine_gradients
from .base import PassResult, ProgressiveIntegrator
from .setup import SceneSetup, compile_by_tracing

#: policies whose unbiasedness tests pass (tests/test_gpt.py, test_gpt_manifold.py) *and* whose deliberately
#: broken variants fail them (the manifold Jacobian's on scenes/caustic-closeup.xml)
SUPPORTED = ("replay", "replay+reconnection", "halfvector+reconnection", "halfvector+reconnection+manifold",
             "halfvector+replay+reconnection")
#: the default wherever the manifold walk does not run: the mixed half-vector policy (on scenes without
#: glossy or specular vertices it runs exactly replay+reconnection's shifts). Measured 2026-12-01 with
#: benchmarks/bench_gpt.py --res 32 --grad-spp 16 --seeds 24 --et-seeds 3 --seconds 4 --threads 1
#: (NUMBA_NUM_THREADS=1, load 1.7-3.1 on 2 cores): gradient error at equal samples, error of whole-path
#: replay / error of the policy (> 1: policy better; +- paired stderr over the 24 seeds):
#:   cornell-box      halfvector+replay+reconnection = replay+reconnection 1.10 +- 0.02, halfvector+reconnection 1.09
#:   fog-box          halfvector+replay+reconnection = replay+reconnection 1.65 +- 0.33, halfvector+reconnection 1.50
#:   mesh             halfvector+replay+reconnection = replay+reconnection 0.83 +- 0.01, halfvector+reconnection 0.82
#:   caustics-box     halfvector+replay+reconnection 0.98 +- 0.05, replay+reconnection 0.95 +- 0.06,
#:                    halfvector+reconnection 0.77 +- 0.04, manifold 0.99 +- 0.11
#:   caustic-closeup  halfvector+replay+reconnection 0.96 +- 0.02, replay+reconnection 0.91 +- 0.03,
#:                    halfvector+reconnection 0.48 +- 0.02, manifold 1.32 +- 0.15
#: so no path-space policy beats halfvector+replay+reconnection where the walk cannot run. Whole-path
#: replay is lower on the mesh scene at equal samples (the reconnection's geometry terms near contacts
#: and facets: book/gpt.md); at equal time (4 s, relMSE against pt 4096 spp, 3 seeds, L1 / L2, this
#: policy vs gpt-replay with the same solver) it is the other way round there: mesh 1.06 / 1.36, Cornell
#: 1.58 / 1.38, fog 1.39 / 1.09; on the two caustic scenes gpt-replay stays ahead at equal time:
#: caustics box 0.93 / 0.76, close-up 0.78 / 0.71 (manifold there 0.83 / 0.83). MANIFOLD_POLICY stays
#: where the plan renders caustics through movable chains: it wins the close-up at equal samples and at
#: equal time; on the caustics box it ties at equal samples and loses to this default with L1 at equal
#: time (0.69 against 0.93; L2 0.83 against 0.76). Equal-time numbers at this load move by ~10 %
#: between identical estimators (replay+reconnection and this policy on the fog box: 1.31 / 1.39).
DEFAULT_POLICY = "halfvector+replay+reconnection"
#: what :func:`default_policy` does, in words (the book quotes it)
DEFAULT_RULE = ("By default gpt takes manifold exploration where the scene's effects plan renders caustics "
                "through specular chains the walk can move (analytic shapes, no media), and "
                "halfvector+replay+reconnection everywhere else.")
MANIFOLD_POLICY = "halfvector+reconnection+manifold"


@njit(cache=True, error_model="numpy")
def gpt_rows(sa, seed, sample0, spp, policy, max_depth, rr_depth, mask, threshold, broken, out, stats, bad):
    """Per-pass means per base pixel in ``out`` (9, H, W, 3): [0] L, the base radiance (pt's primal
    sample); [1 + k] D_k, the gradient sample of shift k (right, left, down, up), sum over techniques
    of w (C' - C), -C for a failed shift; [5 + k] S_k, the weighted offset contribution sum w C' (0 for
    failed or outside shifts). ``stats`` (H, N_STATS) shift counters per row, ``bad`` (H,) dropped
    non-finite samples (the whole sample is dropped). ``gpt_volume.gpt_volume_rows`` has the same
    signature and contract."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed, as pt)
    _gpt_rows(borrowed(sa), seed, sample0, spp, policy, max_depth, rr_depth, mask, threshold, broken, out, stats,
              bad, np.full((1, SH_WIDTH), -1.0))


@njit(cache=True, error_model="numpy")
def gpt_manifold_rows(sa, seed, sample0, spp, policy, max_depth, rr_depth, mask, threshold, broken, out, stats, bad,
                      mtab):
    """:func:`gpt_rows` with the manifold shape table ``mtab`` (:func:`gdlearn.kernels.gpt_manifold.manifold_table`)
    for the policy ``halfvector+reconnection+manifold``."""
    _gpt_rows(borrowed(sa), seed, sample0, spp, policy, max_depth, rr_depth, mask, threshold, broken, out, stats,
              bad, mtab)


@njit(cache=True, error_model="numpy", parallel=True)
def _gpt_rows(sa, seed, sample0, spp, policy, max_depth, rr_depth, mask, threshold, broken, out, stats, bad, mtab):
    h, w = out.shape[1], out.shape[2]
    inv = 1.0 / spp
    for y in prange(h):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        of = np.zeros((4, NF))
        oi = np.zeros((4, NI), dtype=np.int64)
        diff = np.zeros((8, 3))
        acc = np.zeros((9, 3))
        cf = np.zeros((MAX_CHAIN + 1, NCF))
        ci = np.zeros((MAX_CHAIN + 1, NCI), dtype=np.int64)
        st = stats[y]
        for x in range(w):
            key = y * w + x
            acc[:] = 0.0
            for s in range(sample0, sample0 + spp):
                fx, fy = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
                if policy == POLICY_REPLAY:      # whole-path replay: no pair can fail (gpt_replay_policy)
                    c = replay_sample(sa, False, fx, fy, x, y, w, h, seed, key, s, max_depth, rr_depth, mask,
                                      threshold, diff, st, stack, broken)
                else:
                    c = gpt_sample(sa, fx, fy, x, y, w, h, seed, key, s, policy, max_depth, rr_depth, mask,
                                   threshold, of, oi, diff, st, stack, mtab, cf, ci, broken)
                if not (np.isfinite(c[0]) and np.isfinite(c[1]) and np.isfinite(c[2]) and np.all(np.isfinite(diff))):
                    bad[y] += 1          # NaN / Inf never reach an image: drop the whole sample
                    continue
                for ch in range(3):
                    acc[0, ch] += c[ch]
                    for k in range(8):
                        acc[1 + k, ch] += diff[k, ch]
            for j in range(9):
                for ch in range(3):
                    out[j, y, x, ch] = acc[j, ch] * inv


def mis_primal(out: np.ndarray) -> np.ndarray:
    """Kettunen et al. 2015's primal image (Sec. 4 of their paper; STAR Sec. 3.5, Eq. 16-17): every
    pair of neighbours (p, q = p + dir_k) has two techniques for I_p, "sample in p" and "sample in q,
    shift back to p", combined by the balance weights of Eq. 17 that the kernel already applied. With
    the kernel's buffers ``out`` (9, H, W, 3) (:func:`gpt_rows`: L, D_k, S_k) pair k estimates

        I_p ~ (S_k - D_k)[p] + S_opp(k)[p + dir_k]      (= w C of p's paths + w' C' of q's offsets)

    where S_k - D_k is w C for a shift that succeeded and C (weight 1) for one that failed. A pair whose
    neighbour lies outside the image has only the first technique with weight 1: L[p]. Each pair is
    unbiased for I_p; the result is their mean (1/4 each)."""
    out = np.asarray(out, dtype=np.float64)
    base = out[0]
    h, w = base.shape[:2]
    acc = np.zeros_like(base)
    for k in range(4):
        dx, dy = int(SHIFT_DX[k]), int(SHIFT_DY[k])
        term = base.copy()
        y0, y1 = max(0, -dy), h - max(0, dy)     # pixels p whose neighbour p + dir_k is inside
        x0, x1 = max(0, -dx), w - max(0, dx)
        own = out[5 + k, y0:y1, x0:x1] - out[1 + k, y0:y1, x0:x1]
        back = out[5 + (k ^ 1), y0 + dy:y1 + dy, x0 + dx:x1 + dx]   # k ^ 1: right <-> left, down <-> up
        term[y0:y1, x0:x1] = own + back
        acc += term
    return 0.25 * acc


def _has_null_or_media(setup) -> bool:
    return bool(setup.media) or setup.has_null


def default_policy(setup) -> str:
    """The policy ``shift=None`` picks for a :class:`~gdlearn.integrators.setup.SceneSetup` (its scene,
    plan and compiled arrays; :data:`DEFAULT_RULE`): :data:`MANIFOLD_POLICY` where the effects plan renders caustics
    through specular chains, the scene has no media and at least one analytic specular shape the walk
    can move, else :data:`DEFAULT_POLICY` (measurements in its comment). The plan decides:
    ``--effects direct`` on a caustic scene renders no caustic, so no manifold code runs."""
    if setup.plan.specular_chains and "caustics" in setup.plan.names and not _has_null_or_media(setup):
        if np.any(manifold_table(setup.scene, setup.sa)[:, 0] >= 0.0):
            return MANIFOLD_POLICY
    return DEFAULT_POLICY


class GradientPathTracer(ProgressiveIntegrator):
    """``make("gpt", scene, shift=None, seed=0, spp_per_pass=1, effects=None, threads=None,
    max_depth=None)``; options as :class:`~gdlearn.integrators.setup.SceneSetup` plus ``shift``, the
    policy name (one of :data:`SUPPORTED`; None: :func:`default_policy` for this scene and plan)."""

    name = "gpt"

    def __init__(self, scene, *, shift: str | None = None, seed: int = 0, spp_per_pass: int = 1, effects=None,
                 threads=None, max_depth=None, sa=None):
        self.setup = st = SceneSetup(scene, effects=effects, max_depth=max_depth, threads=threads, sa=sa)
        super().__init__(st.scene, seed=seed, spp_per_pass=spp_per_pass)
        if shift is None:
            shift = default_policy(st)
        code = policy_code(shift)
        if shift not in SUPPORTED:
            raise ValueError(f"gpt: shift policy {shift!r} is not supported by this integrator yet; fix: use "
                             f"one of {', '.join(SUPPORTED)}")
        assert POLICIES[shift] == code
        self.shift, self.policy = shift, code
        self.kernel, self.mtab = gpt_rows, None
        if _has_null_or_media(st):
            self.kernel = gpt_volume_rows
            if code == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD:
                raise ValueError("gpt: manifold exploration is not implemented in media; fix: use --shift "
                                 "halfvector+reconnection")
        elif code == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD:
            mtab = manifold_table(st.scene, st.sa)
            if st.plan.specular_chains and np.any(mtab[:, 0] >= 0.0):
                self.kernel, self.mtab = gpt_manifold_rows, mtab
            else:
                # no specular chain the walk could move: the manifold code does not run (same estimator)
                self.policy = POLICY_HALFVECTOR_RECONNECTION
        #: True when the manifold walk runs for this scene (plan + analytic specular shapes)
        self.manifold = self.mtab is not None
        #: fault injection for the tests (gpt_shift.BROKEN_*): a deliberately biased estimator the
        #: unbiasedness tests must reject; 0 is the estimator
        self.broken = 0

    def trace(self, sample0: int, spp: int):
        st = self.setup
        h, w = st.height, st.width
        out = np.zeros((9, h, w, 3))
        stats = np.zeros((h, N_STATS), dtype=np.int64)
        bad = np.zeros(h, dtype=np.int64)
        with st.parallel(h):
            args = (st.sa, self.seed, sample0, spp, self.policy, st.max_depth, st.rr_depth, st.mask,
                    st.threshold, self.broken, out, stats, bad)
            if self.mtab is not None:
                self.kernel(*args, self.mtab)
            else:
                self.kernel(*args)
        return out, stats.sum(axis=0), int(bad.sum())

    def compile(self) -> float:
        return compile_by_tracing(self)

    def render_pass(self, pass_index: int) -> PassResult:
        t0 = time.perf_counter()
        out, st, nbad = self.trace(pass_index * self.spp_per_pass, self.spp_per_pass)
        t1 = time.perf_counter()
        # MIS weights are already inside the buffers: forward and backward are summed (Eq. 16)
        gx, gy = combine_gradients(out[1:5], (1.0, 1.0))
        primal = mis_primal(out)
        t2 = time.perf_counter()
        stats = {"paths": self.setup.width * self.setup.height * self.spp_per_pass, "nonfinite_samples": nbad}
        for action, c in stats_dict(st).items():
            for outcome, v in c.items():
                stats[f"shift_{action}_{outcome}"] = v
        return PassResult(images={"primal": primal, "primal_base": out[0], "gx": gx, "gy": gy}, spp=self.spp_per_pass,
                          timings={"trace": t1 - t0, "combine": t2 - t1}, stats=stats)
