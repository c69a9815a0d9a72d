"""The proof-of-concept gradient-domain path tracer ("gpt-replay"): random-sequence replay.

Hua et al. 2019 (the STAR), Sec. 2.3, Algorithm 1 ``simpleGradientPathTracing``: every
base path of pixel p is the primal path tracer's (:mod:`gdlearn.integrators.path.pt`: Mitsuba's ``path``
or ``volpath``, same kernels, same random numbers), and its random numbers are replayed through the
four neighbours (:mod:`gdlearn.shifts.replay`). A pass yields the primal mean and the forward
difference gradients gx, gy (Eq. 8, both shift directions weighted 0.5, Eq. 16-17), which the
reconstructions of :mod:`gdlearn.reconstruct` turn into the final image. Book chapter:
``book/gpt-replay.md``.

Layout of one pass. Rows are distributed over threads with ``prange``; a row writes only its own
pixels of five per-base-pixel buffers -- the primal and the mean (offset - base) of each shift
(right, left, down, up). A backward shift of pixel (x+1, y) and the forward shift of (x, y) estimate
the same gradient but belong to different base pixels (possibly different rows, for gy): keeping
them apart and combining afterwards (:func:`gdlearn.integrators.gradients.combine_gradients`) means no two
threads ever add into one element. The base image is bit-identical to ``pt``'s with the same seed
(tested).

Cost: a base path plus up to four offset paths per sample, about 5x a path-tracing sample
(``benchmarks/bench_gpt_replay.py`` measures it). Where ``pt`` traces packets, so does this
(:mod:`gdlearn.integrators.path.gpt_replay_packet`). Stage timing ``trace`` covers base and offset
paths together (they are interleaved per sample); ``combine`` the gradient assembly.
"""
from __future__ import annotations

import time

import numpy as np
from numba import prange

from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.geometry import INFO_SHAPE
from gdlearn.kernels.rng import rand
from gdlearn.integrators.path.accumulate import store_means
from gdlearn.integrators.path.surface import radiance_path
from gdlearn.integrators.path import packet as surface_packet
from gdlearn.integrators.path import packet_volume as volume_packet
from gdlearn.integrators.path.gpt_replay_packet import replay_rows_packet, replay_rows_packet_volume
from gdlearn.integrators.path.volume import radiance_volpath
from gdlearn.kernels.arrays import borrowed
from gdlearn.integrators.gradients import combine_gradients
from gdlearn.shifts.replay import SHIFT_WEIGHTS, offset_film_position, shift_q
from gdlearn.integrators.base import PassResult, ProgressiveIntegrator
from gdlearn.integrators.setup import SceneSetup, compile_by_tracing
from gdlearn.kernels.jit import block, ir_inline, rows

#: counters per row, in the order of the ``counts`` array of the kernels
COUNT_NAMES = ("shifts_traced", "shifts_outside", "shifts_rr_skipped", "nonfinite_samples")
#: diagnostic channels per base pixel (``diag`` array): sums over traced shifts
DIAG_ABS_DIFF, DIAG_BASE, DIAG_SHIFTS, DIAG_OTHER_SURFACE = range(4)


@ir_inline
def _finite(c):
    return np.isfinite(c[0]) and np.isfinite(c[1]) and np.isfinite(c[2])


@ir_inline
def _record(acc, j, c, scale):
    acc[j, 0] += c[0] * scale
    acc[j, 1] += c[1] * scale
    acc[j, 2] += c[2] * scale


@ir_inline
def _diagnose(sa, diag, y, x, base, off, fx, fy, ox, oy, stack):
    """|offset - base| and whether the offset's camera ray first hits another shape than the base's
    (the commonest reason replay decorrelates: the paths start on different surfaces)."""
    mb = (base[0] + base[1] + base[2]) / 3.0
    diag[y, x, DIAG_ABS_DIFF] += abs((off[0] + off[1] + off[2]) / 3.0 - mb)
    diag[y, x, DIAG_BASE] += mb
    diag[y, x, DIAG_SHIFTS] += 1.0
    o, d, tmax = camera_ray(sa.camera, fx, fy)
    pb = closest_hit(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)[1]
    o, d, tmax = camera_ray(sa.camera, ox, oy)
    po = closest_hit(sa.nodes, sa.node_info, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)[1]
    sb = sa.prim_info[pb, INFO_SHAPE] if pb >= 0 else -1
    so = sa.prim_info[po, INFO_SHAPE] if po >= 0 else -1
    if sb != so:
        diag[y, x, DIAG_OTHER_SURFACE] += 1.0


@block
def replay_rows_path(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold, rr_min,
                     out, counts, diag, want_diag):
    """Algorithm 1's sampling loop on surfaces (Mitsuba ``path``).

    ``out`` (5, H, W, 3): [0] the primal mean of samples sample0 .. sample0+spp-1 of every pixel,
    [1 + k] the mean of (offset - base) / q of shift k (right, left, down, up; 0 where it left the
    image). ``counts`` (H, 4): per row, :data:`COUNT_NAMES`. ``diag`` (H, W, 4) is filled only if
    ``want_diag`` (see :func:`_diagnose`). A non-finite base drops the sample with its shifts, a
    non-finite offset drops that shift; both are counted.
    """
    # borrowed arrays: no atomic reference counts shared by the threads (kernels.arrays.borrowed)
    _replay_rows_path(borrowed(sa), seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold,
                     rr_min, out, counts, diag, want_diag)


@block
def replay_rows_volpath(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold, rr_min,
                     out, counts, diag, want_diag):
    """As :func:`replay_rows_path` with media (Mitsuba ``volpath``)."""
    # borrowed arrays: no atomic reference counts shared by the threads (kernels.arrays.borrowed)
    _replay_rows_volpath(borrowed(sa), seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold,
                     rr_min, out, counts, diag, want_diag)


def _replay_rows(radiance):
    """The parallel rows of :func:`replay_rows_path` (``radiance_path``) or
    :func:`replay_rows_volpath` (``radiance_volpath``). A factory, not a dispatcher argument: numba
    caches a closure over a compiled function (``kernels.jit._ClosureCache``), not a kernel that takes
    one as an argument."""

    @rows
    def replay(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold, rr_min, out, counts,
               diag, want_diag):
        h, w = out.shape[1], out.shape[2]
        inv = 1.0 / spp
        for row in prange(h):
            y = np.int64(row)     # see kernels.jit: one type for the row index
            stack = np.empty(STACK_SIZE, dtype=np.int32)
            acc = np.zeros((5, 3))
            cnt = counts[y]
            for x in range(w):
                key = y * w + x
                acc[:] = 0.0
                for s in range(sample0, sample0 + spp):
                    fx, fy = x + rand(seed, key, s, 0), y + rand(seed, key, s, 1)
                    o, d, tmax = camera_ray(sa.camera, fx, fy)
                    base = radiance(sa, o, d, tmax, seed, key, s, max_depth, rr_depth, mask, threshold, stack)
                    if not _finite(base):
                        cnt[3] += 1
                        continue
                    _record(acc, 0, base, 1.0)
                    for k in range(4):
                        q = shift_q(x, y, k, w, h, base, seed, key, s, rr_threshold, rr_min, cnt)
                        if q == 0.0:
                            continue
                        ox, oy = offset_film_position(fx, fy, k)
                        o, d, tmax = camera_ray(sa.camera, ox, oy)
                        # same key: the base pixel's random numbers, replayed (Eq. 6-7)
                        off = radiance(sa, o, d, tmax, seed, key, s, max_depth, rr_depth, mask, threshold, stack)
                        if not _finite(off):
                            cnt[3] += 1
                            continue
                        cnt[0] += 1
                        _record(acc, 1 + k, (off[0] - base[0], off[1] - base[1], off[2] - base[2]), 1.0 / q)
                        if want_diag:
                            _diagnose(sa, diag, y, x, base, off, fx, fy, ox, oy, stack)
                store_means(out, y, x, acc, inv)

    return replay


_replay_rows_path = _replay_rows(radiance_path)
_replay_rows_volpath = _replay_rows(radiance_volpath)


class ReplayGPT(ProgressiveIntegrator):
    """``make("gpt-replay", scene, seed=0, spp_per_pass=1, effects=None, threads=None,
    max_depth=None, shift_weights=(0.5, 0.5), shift_rr=0.0, shift_rr_min=0.1, packets=None)``.

    Options as :class:`~gdlearn.integrators.setup.SceneSetup`, plus:

    * ``packets``: as ``pt``'s (:mod:`gdlearn.integrators.path.gpt_replay_packet`: the same buffers
      bit for bit where :func:`gdlearn.integrators.path.packet.eligible` or, with media,
      :func:`gdlearn.integrators.path.packet_volume.eligible` accepts the scene); the
      decorrelation diagnostics always trace one path at a time.

    * ``shift_weights`` (forward, backward): Eq. 16's constant weights; they must sum to 1 (any
      such pair is unbiased; 0.5 / 0.5 is Eq. 17 under replay).
    * ``shift_rr``: Russian roulette on shifts. 0 (default) traces every shift; a positive value is
      the base brightness (mean rgb) above which a shift is always traced, below it with
      probability q = max(mean / shift_rr, shift_rr_min), the kept difference weighted 1/q
      (unbiased: :func:`gdlearn.shifts.replay.shift_survival`).
    """

    name = "gpt-replay"

    def __init__(self, scene, *, shift_weights=SHIFT_WEIGHTS, shift_rr: float = 0.0, shift_rr_min: float = 0.1,
                 seed: int = 0, spp_per_pass: int = 1, effects=None, threads=None, max_depth=None, sa=None,
                 packets=None):
        self.setup = st = SceneSetup(scene, effects=effects, max_depth=max_depth, threads=threads, sa=sa)
        super().__init__(st.scene, seed=seed, spp_per_pass=spp_per_pass)
        wf, wb = (float(v) for v in shift_weights)
        if not abs(wf + wb - 1.0) < 1e-12:
            raise ValueError(f"shift_weights={shift_weights!r}: forward + backward must be 1 (0.5, 0.5 "
                             "is the STAR's choice); other sums scale every gradient")
        if not shift_rr >= 0.0 or not 0.0 < shift_rr_min <= 1.0:
            raise ValueError(f"shift_rr={shift_rr!r} must be >= 0 (0 = off) and shift_rr_min={shift_rr_min!r} "
                             "in (0, 1] (a zero floor would bias gradients of black base paths)")
        self.shift_weights = (wf, wb)
        self.shift_rr, self.shift_rr_min = float(shift_rr), float(shift_rr_min)
        tracer = volume_packet if st.media else surface_packet
        can_pack = tracer.eligible(st.sa, st.mask, st.max_depth, st.plan.possible_mask)
        self.packets = surface_packet.use_packets(packets, can_pack, (
            "integrators/path/packet.py, packet_volume.py: no environment, every effect the scene can show kept, "
            "no null BSDF without media"))
        self.replay_kernel = replay_rows_volpath if st.media else replay_rows_path
        self.packet_kernel = replay_rows_packet_volume if st.media else replay_rows_packet

    def trace(self, sample0: int, spp: int, diagnose: bool = False):
        """Run the kernel once: (out (5, H, W, 3), counts dict, diag (H, W, 4) or None)."""
        st = self.setup
        h, w = st.height, st.width
        out = np.zeros((5, h, w, 3))
        counts = np.zeros((h, 4), dtype=np.int64)
        diag = np.zeros((h, w, 4) if diagnose else (1, 1, 4))
        kernel = self.packet_kernel if self.packets and not diagnose else self.replay_kernel
        with st.parallel(h):
            kernel(st.sa, self.seed, sample0, spp, st.max_depth, st.rr_depth, st.mask, st.threshold,
                   self.shift_rr, self.shift_rr_min, out, counts, diag, diagnose)
        return out, dict(zip(COUNT_NAMES, (int(v) for v in counts.sum(axis=0)))), (diag if diagnose else None)

    def compile(self) -> float:
        return compile_by_tracing(self)

    def render_pass(self, pass_index: int) -> PassResult:
        t0 = time.perf_counter()
        out, counts, _ = self.trace(pass_index * self.spp_per_pass, self.spp_per_pass)
        t1 = time.perf_counter()
        gx, gy = combine_gradients(out[1:], self.shift_weights)
        t2 = time.perf_counter()
        stats = {"paths": self.setup.width * self.setup.height * self.spp_per_pass, **counts}
        return PassResult(images={"primal": out[0], "gx": gx, "gy": gy}, spp=self.spp_per_pass,
                          timings={"trace": t1 - t0, "combine": t2 - t1}, stats=stats)

    def decorrelation(self, spp: int, sample0: int = 0) -> dict[str, np.ndarray]:
        """Where replay produces poorly correlated offsets (book chapter, "where replay fails").

        Traces ``spp`` samples with diagnostics and returns per-pixel maps over the shifts of each
        base pixel: ``relative`` = mean |offset - base| / mean base (mean rgb), ``other_surface`` =
        fraction of shifts whose camera ray first hits another shape than the base's, and
        ``primal``."""
        out, _, diag = self.trace(sample0, spp, diagnose=True)
        n = np.maximum(diag[..., DIAG_SHIFTS], 1.0)
        mean_abs, mean_base = diag[..., DIAG_ABS_DIFF] / n, diag[..., DIAG_BASE] / n
        rel = np.where(mean_base > 0, mean_abs / np.maximum(mean_base, 1e-300), np.where(mean_abs > 0, np.inf, 0.0))
        return {"relative": rel, "other_surface": diag[..., DIAG_OTHER_SURFACE] / n, "primal": out[0]}
