"""The primal path tracer ("pt"): Mitsuba 3's ``path`` / ``volpath`` as a progressive estimator.

One pass renders ``spp_per_pass`` samples in every pixel. Rows are distributed over the threads
in dynamic chunks (:func:`gdlearn.kernels.threads.run_rows`, so the costlier rows of a scene do not
idle a core; no parallel kernel to compile); every row
writes only its own pixels, and every random number is ``rand(seed, pixel key, sample index, dim)``
-- so the image is the same for 1 and 2 threads and for any pass split. The threads share the scene
as *borrowed* arrays (:func:`gdlearn.kernels.arrays.borrowed`): with the owned arrays every kernel call
updated the same atomic reference counts from both cores, and 2 threads were barely faster than 1.

The per-path kernels live in :mod:`gdlearn.integrators.path.surface` (``path``: surfaces only) and
:mod:`gdlearn.integrators.path.volume` (``volpath``: homogeneous media, null interfaces, camera medium).
A scene whose effects plan needs no media never compiles or runs the volume kernel. Scenes
rendered whole (every effect they can show, no environment, no ``transport`` split) are traced in
packets of 64 paths (:mod:`gdlearn.integrators.path.packet`, and
:mod:`gdlearn.integrators.path.packet_volume` with media): the same image bit for bit, ~1.5x
faster per core on the Cornell box (its diffuse lanes shaded in SIMD), ~1.1x on the fog box (128²,
one thread, 2026-12-07).
"""
from __future__ import annotations

import time

import numpy as np

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.camera import camera_ray
from gdlearn.kernels.rng import rand
from gdlearn.integrators.path import packet as surface_packet
from gdlearn.integrators.path.packet import render_row_packet
from gdlearn.integrators.path.packet_rows import new_buffers
from gdlearn.integrators.path import packet_volume as volume_packet
from gdlearn.integrators.path.packet_volume import render_row_packet_volume
from gdlearn.integrators.path.surface import radiance_path_inline
from gdlearn.integrators.path.volume import radiance_volpath_inline
from gdlearn.kernels.arrays import borrowed
from gdlearn.integrators.base import PassResult, ProgressiveIntegrator
from gdlearn.integrators.setup import SceneSetup
from gdlearn.kernels.jit import block
from gdlearn.kernels.pathclass import MEDIA_TRANSPORT, SURFACE_TRANSPORT
from gdlearn.kernels.threads import next_rows, run_rows

#: ``transport`` -> the effects-mask bit it sets (kernels.pathclass, "The camera's end")
TRANSPORT = {"all": 0, "media": MEDIA_TRANSPORT, "surfaces": SURFACE_TRANSPORT}


def _one_path_rows(radiance):
    """The row driver of the one-path-at-a-time kernels: ``radiance`` (``radiance_path_inline`` or
    ``radiance_volpath_inline``) per sample. A factory, not a dispatcher argument: numba never
    caches a kernel that takes a function as an argument (every process compiled it again, ~40 s),
    and it does cache a closure over one (``kernels.jit._ClosureCache``)."""

    @block(nogil=True)
    def rows(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad, counter, step):
        """One thread's share of a pass: chunks of ``step`` rows from ``counter``."""
        sa = borrowed(sa)      # no atomic reference counts shared by the threads (kernels.arrays.borrowed)
        h, w = out.shape[0], out.shape[1]
        inv = 1.0 / spp
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        while True:
            y0, y1 = next_rows(counter, step, h)
            if y0 == y1:
                return
            for y in range(y0, y1):
                nbad = 0
                for x in range(w):
                    key = y * w + x
                    a0 = 0.0
                    a1 = 0.0
                    a2 = 0.0
                    for s in range(sample0, sample0 + spp):
                        o, d, tmax = camera_ray(sa.camera, x + rand(seed, key, s, 0), y + rand(seed, key, s, 1))
                        c = radiance(sa, o, d, tmax, seed, key, s, max_depth, rr_depth, mask, threshold, stack)
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

    return rows


_rows_path = _one_path_rows(radiance_path_inline)
_rows_volpath = _one_path_rows(radiance_volpath_inline)


def render_rows_path(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """Surfaces only (Mitsuba ``path``): the mean radiance of samples sample0 .. sample0+spp-1 of
    every pixel into ``out`` (H x W x 3); ``bad[y]`` counts the non-finite samples dropped in row y."""
    run_rows(lambda counter, step: _rows_path(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out,
                                              bad, counter, step), out.shape[0])


def render_rows_packet(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """As :func:`render_rows_path`, traced in packets of paths (:mod:`gdlearn.integrators.path.packet`;
    the same image bit for bit, for the scenes it accepts)."""
    run_rows(lambda counter, step: _rows_packet(sa, seed, sample0, spp, max_depth, rr_depth, out, bad, counter,
                                                step), out.shape[0])


@block(nogil=True)
def _rows_packet(sa, seed, sample0, spp, max_depth, rr_depth, out, bad, counter, step):
    sa = borrowed(sa)
    h = out.shape[0]
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    S, Q, buf, items = new_buffers()
    acc = np.zeros((out.shape[1], 3))
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            bad[y] = render_row_packet(sa, y, seed, sample0, spp, max_depth, rr_depth, out, S, Q, buf, items, acc,
                                       stack)


def render_rows_packet_volume(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """As :func:`render_rows_volpath`, traced in packets (:mod:`gdlearn.integrators.path.packet_volume`)."""
    run_rows(lambda counter, step: _rows_packet_volume(sa, seed, sample0, spp, max_depth, rr_depth, out, bad,
                                                       counter, step), out.shape[0])


@block(nogil=True)
def _rows_packet_volume(sa, seed, sample0, spp, max_depth, rr_depth, out, bad, counter, step):
    sa = borrowed(sa)
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    _, _, buf, items = new_buffers()
    S, Q = volume_packet.new_buffers()
    acc = np.zeros((out.shape[1], 3))
    while True:
        y0, y1 = next_rows(counter, step, out.shape[0])
        if y0 == y1:
            return
        for y in range(y0, y1):
            bad[y] = render_row_packet_volume(sa, y, seed, sample0, spp, max_depth, rr_depth, out, S, Q, buf, items,
                                              acc, stack)


def render_rows_volpath(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out, bad):
    """As :func:`render_rows_path` with media (Mitsuba ``volpath``)."""
    run_rows(lambda counter, step: _rows_volpath(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, out,
                                                 bad, counter, step), out.shape[0])


class PathTracer(ProgressiveIntegrator):
    """``make("pt", scene, seed=0, spp_per_pass=1, effects=None, transport="all", threads=None,
    max_depth=None, packets=None)``.

    ``max_depth``, ``threads`` and ``effects`` as :class:`~gdlearn.integrators.setup.SceneSetup`
    (``self.setup``); ``packets``: None traces in packets where :mod:`gdlearn.integrators.path.packet`
    accepts the scene, False forces the one-path-at-a-time kernel, True insists (ValueError if the
    scene is not eligible). ``transport="media"`` keeps only light transport ending in the medium
    (the first non-specular camera vertex a medium scattering event, ``pathclass.MEDIA_TRANSPORT``):
    the unbiased reference of the volumetric photon estimators' ``transport="media"``;
    ``"surfaces"`` keeps the rest, so the two add up to the full image.
    """

    name = "pt"

    def __init__(self, scene, *, seed: int = 0, spp_per_pass: int = 1, effects=None, transport: str = "all",
                 threads=None, max_depth=None, sa=None, packets=None):
        if transport not in TRANSPORT:
            raise ValueError(f"transport={transport!r}: choose one of {', '.join(TRANSPORT)}")
        self.setup = s = SceneSetup(scene, effects=effects, max_depth=max_depth, threads=threads, sa=sa)
        if transport != "all":
            if not s.plan.media:
                raise ValueError(f"transport={transport!r} splits the image at the camera path's first medium "
                                 "scattering event, and this scene (or its effects plan) has no medium; fix: "
                                 "transport='all'")
            s.mask |= TRANSPORT[transport]
        self.transport = transport
        super().__init__(s.scene, seed=seed, spp_per_pass=spp_per_pass)
        if s.media:
            can_pack = volume_packet.eligible(s.sa, s.mask, s.max_depth, s.plan.possible_mask)
        else:
            can_pack = surface_packet.eligible(s.sa, s.mask, s.max_depth, s.plan.possible_mask)
        self.packets = surface_packet.use_packets(packets, can_pack, (
            "integrators/path/packet.py, packet_volume.py: no environment, every effect the scene can show kept, no "
            "transport split; without media, no null BSDF"))
        if s.media:
            self.kernel = render_rows_packet_volume if self.packets else render_rows_volpath
        else:
            self.kernel = render_rows_packet if self.packets else render_rows_path

    def _run(self, sample0, spp, out):
        s = self.setup
        bad = np.zeros(out.shape[0], dtype=np.int64)
        with s.parallel(out.shape[0]):
            self.kernel(s.sa, self.seed, sample0, spp, s.max_depth, s.rr_depth, s.mask, s.threshold, out, bad)
        return int(bad.sum())

    def compile(self) -> float:
        t0 = time.perf_counter()
        self._run(0, 1, np.zeros((2, 2, 3)))
        return time.perf_counter() - t0

    def render_pass(self, pass_index: int) -> PassResult:
        s = self.setup
        out = np.zeros((s.height, s.width, 3))
        t0 = time.perf_counter()
        nbad = self._run(pass_index * self.spp_per_pass, self.spp_per_pass, out)
        dt = time.perf_counter() - t0
        n = s.width * s.height * self.spp_per_pass
        return PassResult(images={"primal": out}, spp=self.spp_per_pass, timings={"trace": dt},
                          stats={"paths": n, "nonfinite_samples": nbad})
