"""Gradient-domain path tracing with shift mappings ("gpt"; Kettunen et al. 2015, STAR Sec. 3-4.1).

Every base path of pixel p (Mitsuba's ``path``, same kernels and random numbers as ``pt``) is shifted
to the four neighbours in lockstep by a combined shift policy (:mod:`!gdlearn.shifts.policy`), and
each base / offset contribution pair is weighted by Eq. 17's balance heuristic
(:mod:`!gdlearn.integrators.path.gpt_surface.lockstep` has the method). The accumulation layout is ``gpt-replay``'s: per
base pixel a primal buffer and four shift buffers (right, left, down, up), written by one row each,
combined afterwards into gx, gy -- with weights (1, 1) here, since the MIS weights are inside the
buffers (forward and backward weights of one path pair sum to one).

The primal image is Kettunen et al.'s MIS-weighted one (:func:`~gdlearn.integrators.gradients.mis_primal`): each path pair also
estimates the pixel value twice, from the base path in p and from the offset path shifted back from
the neighbour, with the same Eq. 17 weights. ``images["primal"]`` is that estimate;
``images["primal_base"]`` is the base radiance alone (``pt``'s estimator, same random numbers).

Policies (``shift=``): ``replay`` (the whole path replayed, :mod:`!gdlearn.integrators.path.gpt_replay_policy`:
``gpt-replay``'s estimator, Eq. 17 weights 1/2), the mixed policies ``replay+reconnection`` and
``halfvector+replay+reconnection`` (:mod:`!gdlearn.integrators.path.gpt_surface.mixed`: reconnect where the criterion
holds from both sides, else replay -- also through a class mismatch -- or copy the half vector between
two non-connectable vertices; fail only where the backward shift would reconnect),
``halfvector+reconnection`` (Kettunen et al.'s: fails on a class mismatch) and
``halfvector+reconnection+manifold`` (Kettunen et al.'s plus manifold exploration of specular chains
between connectable vertices, :mod:`!gdlearn.integrators.path.gpt_surface.manifold`). The manifold walk runs only where
the effects plan has specular chains and the scene has analytic specular shapes (``self.manifold``);
elsewhere that policy is halfvector+reconnection. Default (``shift=None``): :func:`default_policy` --
:data:`DEFAULT_RULE`; manifold exploration is asked for by name (the measurements are in
benchmarks/README.md, "Which policy by default"). Scenes with media or
null interfaces run the twin kernel :func:`!gdlearn.integrators.path.gpt_volume.lockstep.gpt_volume_rows` (same
signature and buffers), imported lazily; it has no manifold walk.

Frame stats: ``paths``, ``nonfinite_samples`` and, per shift action, ``shift_<action>_{run,ok,failed}``
(actions: replay, halfvector, reconnection, manifold, fail) counted over offset path segments.
"""
from __future__ import annotations

import time

import numpy as np
from numba import prange

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.integrators.path.gpt_surface.lockstep import gpt_sample
from gdlearn.integrators.path.gpt_surface.manifold import NCF, NCI, manifold_table
from gdlearn.integrators.path.gpt_replay_policy import replay_sample
from gdlearn.integrators.path.gpt_surface.vertex import NF, NI
from gdlearn.integrators.path.gpt_volume.lockstep import gpt_volume_rows
from gdlearn.kernels.rng import rand
from gdlearn.kernels.arrays import borrowed
from gdlearn.shifts.policy import (MAX_CHAIN, N_STATS, POLICIES, POLICY_HALFVECTOR_RECONNECTION, POLICY_REPLAY,
                             POLICY_HALFVECTOR_RECONNECTION_MANIFOLD, policy_code, stats_dict)
from gdlearn.integrators.gradients import combine_gradients, mis_primal
from gdlearn.integrators.path.params import GptParams, PathRng, Pixel
from gdlearn.integrators.path.accumulate import add_sample, finite_sample, store_means
from gdlearn.integrators.base import PassResult, ProgressiveIntegrator
from gdlearn.integrators.setup import SceneSetup, compile_by_tracing
from gdlearn.kernels.jit import block, rows
from gdlearn.kernels.threads import next_rows, run_rows

#: policies whose unbiasedness tests pass (tests/test_gpt.py, test_gpt_manifold.py) *and* whose deliberately
#: broken variants fail them (the manifold Jacobian's on scenes/caustic-closeup.xml)
SUPPORTED = ("replay", "replay+reconnection", "halfvector+reconnection", "halfvector+reconnection+manifold",
             "halfvector+replay+reconnection")
#: the default policy on every surface scene: the mixed half-vector policy (on scenes without glossy or
#: specular vertices it runs exactly replay+reconnection's shifts); the measurements behind the choice
#: (gradient error at equal samples, equal-time relMSE per scene) are in benchmarks/README.md, bench_gpt
DEFAULT_POLICY = "halfvector+replay+reconnection"
#: what :func:`default_policy` does, in words (the book quotes it)
DEFAULT_RULE = ("By default gpt takes halfvector+replay+reconnection on every scene; manifold exploration "
                "(halfvector+reconnection+manifold) runs only when asked for, and then only where the effects "
                "plan renders specular chains the walk can move (analytic shapes, no media). At equal time "
                "(128 x 128 pixels, 20 s, 3 seeds) the manifold policy had 2.0-3.2 times the default's relMSE "
                "on the glass scenes, the caustics box and the glass ball's close-up, with all effects or the "
                "caustics alone: it copies half vectors where the default replays, and pays for its walk. Only "
                "the mirror sphere's caustic gained from it, by 1.14 times, and its kernel takes a minute and a "
                "half longer to compile.")
MANIFOLD_POLICY = "halfvector+reconnection+manifold"
#: the classes (kernels.pathclass) of every surface path that has crossed a specular chain between two
#: connectable vertices (or a connectable vertex and the light): it has a specular vertex and at least
#: two interior ones. The manifold walk changes contributions of these classes only.
CHAIN_CLASSES = ("specular", "caustics")


def gpt_rows(sa, seed, sample0, spp, cfg, out, stats, bad):
    """Per-pass means per base pixel in ``out`` (9, H, W, 3): [0] L, the base radiance (pt's primal
    sample); [1 + k] D_k, the gradient sample of shift k (right, left, down, up), sum over techniques
    of w (C' - C), -C for a failed shift; [5 + k] S_k, the weighted offset contribution sum w C' (0 for
    failed or outside shifts). ``stats`` (H, N_STATS) shift counters per row, ``bad`` (H,) dropped
    non-finite samples (the whole sample is dropped). ``gpt_volume.gpt_volume_rows`` has the same
    signature and contract. The rows run on threads, each taking chunks of rows until the image is
    done (``kernels.threads.run_rows``): no parallel kernel to compile, a third of gpt's cold compile."""
    run_rows(lambda counter, step: _gpt_rows(sa, seed, sample0, spp, cfg, out, stats, bad, None, counter, step),
             out.shape[1])     # None: no manifold code


def gpt_manifold_rows(sa, seed, sample0, spp, cfg, out, stats, bad, mtab):
    """:func:`gpt_rows` with the manifold shape table ``mtab`` (:func:`gdlearn.integrators.path.gpt_surface.manifold.manifold_table`)
    for the policy ``halfvector+reconnection+manifold``."""
    run_rows(lambda counter, step: _gpt_rows(sa, seed, sample0, spp, cfg, out, stats, bad, mtab, counter, step),
             out.shape[1])


@block
def gpt_replay_policy_rows(sa, seed, sample0, spp, cfg, out, stats, bad, volume):
    """:func:`gpt_rows` for the policy ``replay`` (whole-path replay, :mod:`gdlearn.integrators.path.gpt_replay_policy`;
    ``volume``: trace with volpath), in a kernel of its own, so that the shift kernels do not compile
    the path tracers they never call."""
    _replay_policy_rows(borrowed(sa), seed, sample0, spp, cfg, out, stats, bad, volume)


@rows
def _replay_policy_rows(sa, seed, sample0, spp, cfg, out, stats, bad, volume):
    h, w = out.shape[1], out.shape[2]
    inv = 1.0 / spp
    for row in prange(h):
        y = np.int64(row)     # see kernels.jit: one type for the row index
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        diff = np.zeros((8, 3))
        acc = np.zeros((9, 3))
        st = stats[y]
        for x in range(w):
            key = y * w + x
            acc[:] = 0.0
            for s in range(sample0, sample0 + spp):
                fx, fy = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
                c = replay_sample(sa, volume, Pixel(fx, fy, x, y, w, h), PathRng(seed, key, s), cfg, diff, st, stack)
                if not finite_sample(c, diff):
                    bad[y] += 1          # NaN / Inf never reach an image: drop the whole sample
                    continue
                add_sample(acc, c, diff)
            store_means(out, y, x, acc, inv)


@block(nogil=True)
def _gpt_rows(sa, seed, sample0, spp, cfg, out, stats, bad, mtab, counter, step):
    """One thread's share of the pass: chunks of ``step`` rows taken from ``counter`` until the image
    is done (:func:`gdlearn.kernels.threads.run_rows` runs it on every thread at once)."""
    # borrowed arrays: no atomic reference counts shared by the threads (kernels.arrays.borrowed, as pt)
    sa = borrowed(sa)
    h, w = out.shape[1], out.shape[2]
    inv = 1.0 / spp
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    of = np.zeros((4, NF))
    oi = np.zeros((4, NI), dtype=np.int64)
    diff = np.zeros((8, 3))
    acc = np.zeros((9, 3))
    cf = np.zeros((MAX_CHAIN + 1, NCF))
    ci = np.zeros((MAX_CHAIN + 1, NCI), dtype=np.int64)
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            st = stats[y]
            for x in range(w):
                key = y * w + x
                acc[:] = 0.0
                for s in range(sample0, sample0 + spp):
                    fx, fy = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
                    c = gpt_sample(sa, Pixel(fx, fy, x, y, w, h), PathRng(seed, key, s), cfg, of, oi, diff, st,
                                   stack, mtab, cf, ci)
                    if not finite_sample(c, diff):
                        bad[y] += 1          # NaN / Inf never reach an image: drop the whole sample
                        continue
                    add_sample(acc, c, diff)
                store_means(out, y, x, acc, inv)


def _has_null_or_media(setup) -> bool:
    return bool(setup.media) or setup.has_null


def select_kernel(setup, code: int):
    """``(kernel, extra, code)``: the rows kernel that renders policy ``code`` on a
    :class:`~gdlearn.integrators.setup.SceneSetup`, the arguments it takes after the common ones, and
    the policy code it runs. Whole-path replay has a kernel of its own (surfaces or media); media and
    null interfaces take the volume kernel; the manifold policy takes the manifold kernel where the
    effects plan renders a class whose paths can cross a specular chain between connectable vertices
    (:data:`CHAIN_CLASSES`) and the walk has an analytic shape to move, else it *is*
    ``halfvector+reconnection``: a walk could change only contributions of classes not rendered, so
    the image is the same estimator's."""
    if code == POLICY_REPLAY:
        return gpt_replay_policy_rows, (_has_null_or_media(setup),), code
    if _has_null_or_media(setup):
        if code == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD:
            raise ValueError("gpt: manifold exploration is not implemented in media; fix: use --shift "
                             "halfvector+reconnection")
        return gpt_volume_rows, (), code
    if code == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD:
        if setup.plan.specular_chains and any(c in setup.plan.names for c in CHAIN_CLASSES):
            mtab = manifold_table(setup.scene, setup.sa)
            if np.any(mtab[:, 0] >= 0.0):
                return gpt_manifold_rows, (mtab,), code
        return gpt_rows, (), POLICY_HALFVECTOR_RECONNECTION
    return gpt_rows, (), code


def default_policy(setup) -> str:
    """The policy ``shift=None`` picks for a :class:`~gdlearn.integrators.setup.SceneSetup`:
    :data:`DEFAULT_POLICY` (:data:`DEFAULT_RULE` says why). ``setup`` is the scene, plan and compiled
    arrays a rule can look at; the measured one needs none of them. Where manifold exploration is
    asked for, ``select_kernel`` lets the effects plan decide whether the walk is compiled at all."""
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
        #: the rows kernel, its arguments after the common ones (the replay kernel's volume flag, the
        #: manifold table) and the policy code it runs (:func:`select_kernel`)
        self.kernel, self.extra, self.policy = select_kernel(st, code)
        #: True when the manifold walk runs for this scene (plan + analytic specular shapes)
        self.manifold = self.kernel is gpt_manifold_rows
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
            args = (st.sa, self.seed, sample0, spp, GptParams.of(st, self.policy, self.broken), out, stats, bad)
            self.kernel(*args, *self.extra)
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
