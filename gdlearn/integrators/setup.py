"""What every integrator derives from a scene before its first pass: :class:`SceneSetup`.

The effects plan, the compiled arrays, the depths Mitsuba's integrator element asks for (clipped by
the plan: a request for direct light only needs paths of two segments), the effects mask and
roughness threshold the kernels test, whether the volume code path runs, the film size and the
thread count. Every estimator family holds one (composition): pt, gpt-replay, gpt and the photon
estimators build the same set-up the same way, and none of them has to subclass another to get it.
"""
from __future__ import annotations

import copy
import time
from contextlib import contextmanager

import numba

from gdlearn.kernels.threads import CHUNKS
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.effects import plan as effects_plan

#: Mitsuba's max_depth = -1 (unbounded) as a loop bound; Russian roulette ends such paths.
UNBOUNDED = 1 << 30


class SceneSetup:
    """``SceneSetup(scene, effects=None, max_depth=None, threads=None, sa=None)``.

    ``max_depth`` overrides the scene integrator's (Mitsuba's meaning, -1 unbounded); ``effects``
    restricts the image to those light paths (:mod:`gdlearn.scene.effects`); ``threads`` sets numba's
    thread count for the passes (None: numba's default); ``sa`` reuses already compiled arrays.

    Attributes: ``scene`` (a copy when ``max_depth`` is overridden: the plan must see the depth that is
    rendered), ``plan``, ``sa``, ``max_depth`` (a loop bound, :data:`UNBOUNDED` for -1), ``rr_depth``,
    ``mask``, ``threshold``, ``media``, ``threads``, ``width``, ``height``.
    """

    def __init__(self, scene, *, effects=None, max_depth=None, threads=None, sa=None):
        if max_depth is not None:
            scene = copy.copy(scene)
            scene.integrator = copy.copy(scene.integrator)
            scene.integrator.max_depth = int(max_depth)
        self.scene = scene
        self.plan = effects_plan(scene, effects)   # names, groups or a comma string
        self.sa = sa if sa is not None else compile_scene(scene, self.plan)
        md = scene.integrator.max_depth
        md = UNBOUNDED if md < 0 else md
        if self.plan.max_interior >= 0:          # the requested effects need no longer paths
            md = min(md, self.plan.max_interior + 1)
        self.max_depth = md
        self.rr_depth = int(scene.integrator.rr_depth)
        self.mask = int(self.plan.mask)
        self.threshold = float(self.plan.roughness_threshold)
        #: the volume kernels run only when the plan needs media (or volpath's null-interface rule)
        self.has_null = any(s.bsdf is not None and s.bsdf.type == "null" for s in scene.shapes)
        self.media = bool(self.plan.media) or (scene.integrator.type == "volpath" and self.has_null)
        self.threads = threads
        self.width, self.height = scene.sensor.film.width, scene.sensor.film.height

    @contextmanager
    def parallel(self, rows: int):
        """Run the enclosed kernel call on ``threads`` threads, rows handed out in dynamic chunks.

        Rows differ in cost (the light, boxes, escaping rays); a static half/half split would leave one
        core idle at the end of every pass, so chunks of a few rows (1/32 of the image) are dealt out."""
        old = numba.get_num_threads()
        if self.threads is not None:
            numba.set_num_threads(int(self.threads))
        try:
            with numba.parallel_chunksize(max(1, rows // CHUNKS)):
                yield
        finally:
            numba.set_num_threads(old)


def compile_by_tracing(integ) -> float:
    """JIT-compile an integrator whose kernels run through ``integ.trace(sample0, spp)``: trace one
    sample of a 2 x 2 image (a tiny image compiles the same kernel types as any size); returns seconds."""
    t0 = time.perf_counter()
    s = integ.setup
    h, w = s.height, s.width
    s.height, s.width = 2, 2
    try:
        integ.trace(0, 1)
    finally:
        s.height, s.width = h, w
    return time.perf_counter() - t0
