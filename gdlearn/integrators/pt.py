"""The primal path tracer ("pt"): Mitsuba 3's ``path`` / ``volpath`` as a progressive estimator.

One pass renders ``spp_per_pass`` samples in every pixel. Rows are distributed over the threads
with ``prange`` (dynamic chunks, so the costlier rows of a scene do not idle a core); every row
writes only its own pixels, and every random number is ``rand(seed, pixel key, sample index, dim)``
-- so the image is the same for 1 and 2 threads and for any pass split. The threads share the scene
as *borrowed* arrays (:func:`gdlearn.scene.compile.borrowed`): with the owned arrays every kernel call
updated the same atomic reference counts from both cores, and 2 threads were barely faster than 1.

The per-path kernels live in :mod:`gdlearn.kernels.surface_path` (``path``: surfaces only) and
:mod:`gdlearn.kernels.volume_path` (``volpath``: homogeneous media, null interfaces, camera medium).
A scene whose effects plan needs no media never compiles or runs the volume kernel. Scenes of
diffuse triangles lit by area emitters (the Cornell box) are traced in packets of 64 paths
(:mod:`gdlearn.kernels.surface_packet`): the same image bit for bit, ~1.35x faster per core.
"""
from __future__ import annotations

import time

import numba
import numpy as np
from numba import njit, prange

from ..kernels.bvh import STACK_SIZE
from ..kernels.camera import camera_ray
from ..kernels.rng import rand
from ..kernels import surface_packet
from ..kernels.surface_packet import render_row_packet
from ..kernels.surface_path import radiance_path_inline
from ..kernels.volume_path import radiance_volpath_inline
from ..scene.effects import plan as effects_plan
from ..scene.compile import borrowed, compile_scene
from .base import PassResult, ProgressiveIntegrator

#: Mitsuba's max_depth = -1 (unbounded) as a loop bound; Russian roulette ends such paths.
UNBOUNDED = 1 << 30


@njit(cache=True, error_model="numpy")
def render_rows_path(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """Surfaces only (Mitsuba ``path``): the mean radiance of samples sample0 .. sample0+spp-1 of
    every pixel into ``out`` (H x W x 3); ``bad[y]`` counts the non-finite samples dropped in row y."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed)
    _rows_path(borrowed(sa), seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad)


# The surface and volume row loops below are twins on purpose: passing the radiance function as an
# argument would merge them, but numba never caches a kernel that takes a dispatcher argument
# (measured: every process recompiles it, ~40 s), and this loop is the hot, cached entry point.
@njit(cache=True, error_model="numpy", parallel=True)
def _rows_path(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    h, w = out.shape[0], out.shape[1]
    inv = 1.0 / spp
    for y in prange(h):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        nbad = 0
        for x in range(w):
            key = y * w + x
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            for s in range(sample0, sample0 + spp):
                o, d, tmax = camera_ray(sa.camera, x + rand(seed, key, s, 0), y + rand(seed, key, s, 1))
                c = radiance_path_inline(sa, o, d, tmax, seed, key, s, max_depth, rr_depth, mask, threshold, stack)
                if np.isfinite(c[0]) and np.isfinite(c[1]) and np.isfinite(c[2]):
                    a0 += c[0]
                    a1 += c[1]
                    a2 += c[2]
                else:
                    nbad += 1
            out[y, x, 0] = a0 * inv
            out[y, x, 1] = a1 * inv
            out[y, x, 2] = a2 * inv
        bad[y] = nbad


@njit(cache=True, error_model="numpy")
def render_rows_packet(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """As :func:`render_rows_path`, traced in packets of paths (:mod:`gdlearn.kernels.surface_packet`;
    the same image bit for bit, for the scenes it accepts)."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed)
    _rows_packet(borrowed(sa), seed, sample0, spp, max_depth, rr_depth, out, bad)


@njit(cache=True, error_model="numpy", parallel=True)
def _rows_packet(sa, seed, sample0, spp, max_depth, rr_depth, out, bad):
    for y in prange(out.shape[0]):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        S, Q, buf = surface_packet.new_buffers()
        bad[y] = render_row_packet(sa, y, seed, sample0, spp, max_depth, rr_depth, out, S, Q, buf, stack)


@njit(cache=True, error_model="numpy")
def render_rows_volpath(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """As :func:`render_rows_path` with media (Mitsuba ``volpath``)."""
    # borrowed arrays: no atomic reference counts shared by the threads (scene.compile.borrowed)
    _rows_volpath(borrowed(sa), seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad)


@njit(cache=True, error_model="numpy", parallel=True)
def _rows_volpath(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    h, w = out.shape[0], out.shape[1]
    inv = 1.0 / spp
    for y in prange(h):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        nbad = 0
        for x in range(w):
            key = y * w + x
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            for s in range(sample0, sample0 + spp):
                o, d, tmax = camera_ray(sa.camera, x + rand(seed, key, s, 0), y + rand(seed, key, s, 1))
                c = radiance_volpath_inline(sa, o, d, tmax, seed, key, s, max_depth, rr_depth, mask, threshold, stack)
                if np.isfinite(c[0]) and np.isfinite(c[1]) and np.isfinite(c[2]):
                    a0 += c[0]
                    a1 += c[1]
                    a2 += c[2]
                else:
                    nbad += 1
            out[y, x, 0] = a0 * inv
            out[y, x, 1] = a1 * inv
            out[y, x, 2] = a2 * inv
        bad[y] = nbad


def compile_by_tracing(integ) -> float:
    """JIT-compile an integrator whose kernels run through ``integ.trace(sample0, spp)``: trace one
    sample of a 2 x 2 image (a tiny image compiles the same kernel types as any size); returns seconds."""
    t0 = time.perf_counter()
    h, w = integ.height, integ.width
    integ.height, integ.width = 2, 2
    try:
        integ.trace(0, 1)
    finally:
        integ.height, integ.width = h, w
    return time.perf_counter() - t0


class PathTracer(ProgressiveIntegrator):
    """``make("pt", scene, seed=0, spp_per_pass=1, effects=None, threads=None, max_depth=None,
    packets=None)``.

    ``max_depth`` overrides the scene integrator's (Mitsuba's meaning); ``threads`` sets numba's
    thread count for this integrator's passes; ``effects`` (a list of effect names, or a comma
    separated string) restricts the image to those light paths (see :mod:`gdlearn.scene.effects`).
    """

    name = "pt"

    def __init__(self, scene, *, seed: int = 0, spp_per_pass: int = 1, effects=None, threads=None,
                 max_depth=None, sa=None, packets=None):
        super().__init__(scene, seed=seed, spp_per_pass=spp_per_pass)
        if max_depth is not None:       # the plan must see the depth that will be rendered
            import copy
            scene = copy.copy(scene)
            scene.integrator = copy.copy(scene.integrator)
            scene.integrator.max_depth = int(max_depth)
            self.scene = scene
        if isinstance(effects, str):
            effects = [e.strip() for e in effects.split(",") if e.strip()]
        self.plan = effects_plan(scene, effects)
        self.sa = sa if sa is not None else compile_scene(scene, self.plan)
        md = scene.integrator.max_depth
        md = UNBOUNDED if md < 0 else md
        if self.plan.max_interior >= 0:          # the requested effects need no longer paths
            md = min(md, self.plan.max_interior + 1)
        self.max_depth = md
        self.rr_depth = int(scene.integrator.rr_depth)
        self.mask = int(self.plan.mask)
        self.threshold = float(self.plan.roughness_threshold)
        # the volume kernel runs only when the plan needs media (or volpath's null-interface rule)
        has_null = any(s.bsdf.type == "null" for s in scene.shapes)
        self.media = bool(self.plan.media) or (scene.integrator.type == "volpath" and has_null)
        # packets of paths for the scenes surface_packet accepts (the same image, faster); packets=False
        # forces the one-path-at-a-time kernel, packets=True insists (ValueError if not eligible)
        can_pack = not self.media and surface_packet.eligible(self.sa, self.mask, self.max_depth)
        if packets and not can_pack:
            raise ValueError("this scene cannot be traced in packets (kernels/surface_packet.py: diffuse BSDFs, area "
                             "emitters, triangles, no media, every diffuse path kept); fix: packets=None or False")
        self.packets = can_pack if packets is None else bool(packets) and can_pack
        self.kernel = render_rows_volpath if self.media else (render_rows_packet if self.packets else render_rows_path)
        self.threads = threads
        self.width, self.height = scene.sensor.film.width, scene.sensor.film.height

    def _run(self, sa, sample0, spp, out):
        bad = np.zeros(out.shape[0], dtype=np.int64)
        old = numba.get_num_threads()
        if self.threads is not None:
            numba.set_num_threads(int(self.threads))
        try:
            # dynamic chunks of a few rows: rows differ in cost (light, boxes, escaping rays), and a
            # static half/half split would leave one core idle at the end of every pass
            with numba.parallel_chunksize(max(1, out.shape[0] // 32)):
                self.kernel(sa, self.seed, sample0, spp, self.max_depth, self.rr_depth, self.mask, self.threshold,
                            out, bad)
        finally:
            numba.set_num_threads(old)
        return int(bad.sum())

    def compile(self) -> float:
        t0 = time.perf_counter()
        self._run(self.sa, 0, 1, np.zeros((2, 2, 3)))
        return time.perf_counter() - t0

    def render_pass(self, pass_index: int) -> PassResult:
        out = np.zeros((self.height, self.width, 3))
        t0 = time.perf_counter()
        nbad = self._run(self.sa, pass_index * self.spp_per_pass, self.spp_per_pass, out)
        dt = time.perf_counter() - t0
        n = self.width * self.height * self.spp_per_pass
        return PassResult(images={"primal": out}, spp=self.spp_per_pass, timings={"trace": dt},
                          stats={"paths": n, "nonfinite_samples": nbad})
