"""One protocol for every estimator: progressive passes that yield :class:`Frame` objects.

Every integrator in gdlearn -- the primal path tracer, the gradient-domain path tracers and the
photon-density estimators -- renders *progressively*: each call of ``render_pass`` adds one pass,
and the shared :class:`ProgressiveIntegrator` folds it into the frame. How passes combine is the
estimator's choice (:mod:`gdlearn.integrators.combine`): a mean of independent passes, or the
estimator's own per-pixel state (SPPM). A frame carries everything the rest of the road needs:

* ``primal``: the primal image (H x W x 3, float64, linear RGB);
* ``gx`` / ``gy``: forward-difference gradient images, ``gx[y, x] ~ I[y, x+1] - I[y, x]`` and
  ``gy[y, x] ~ I[y+1, x] - I[y, x]`` (None for primal-only estimators);
* two independent half-buffers of every image, from which the weighted reconstructions estimate
  per-pixel variances (:meth:`Frame.variance`);
* shift statistics (success / failure / null / mixed counts) and non-finite-sample counts, summed
  over passes; ``state``, values that are not summed (a radius, alpha, photons emitted: the last
  pass's value); ``photons``, the light paths emitted so far (the photon estimators' normalisation
  and budget);
* the wall time of each stage (``trace``, ``photons``, ``build``, ``gather``, ...), with JIT
  compilation kept apart in ``compile``, so the experiments module can compare estimators at equal
  time.

An integrator subclass implements :meth:`ProgressiveIntegrator.render_pass` (photon estimators:
the four stages of :class:`gdlearn.integrators.photon_base.PhotonPassIntegrator`) and usually
:meth:`ProgressiveIntegrator.compile`. :func:`render` runs one to a budget in samples per pixel,
seconds, passes or photons.
"""
from __future__ import annotations

import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from gdlearn.integrators.combine import LatestEstimate, MeanOfPasses


@dataclass
class PassResult:
    """What one pass returns.

    ``images``: per-pixel *means over this pass's samples* (:class:`MeanOfPasses`) or the estimator's
    current full estimate (:class:`LatestEstimate`); ``spp``: the pass's camera samples per pixel;
    ``timings``: its stage wall times (seconds); ``stats``: counters, summed over passes; ``state``:
    values that are not summed (last value wins); ``halves``: ``{name: (a, b)}``, two independent
    estimates made inside the pass (at equal radius), when the pass makes them itself; ``photons``:
    light paths emitted in this pass."""
    images: dict[str, np.ndarray]
    spp: int
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, int] = field(default_factory=dict)
    state: dict[str, object] = field(default_factory=dict)
    halves: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
    photons: int = 0


@dataclass
class Frame:
    """The accumulated state after ``passes`` passes (see the module docstring)."""
    passes: int
    spp: int
    images: dict[str, np.ndarray]
    halves: dict[str, tuple[np.ndarray, np.ndarray]]
    timings: dict[str, float]
    stats: dict[str, int]
    elapsed: float                    # wall seconds spent in passes, JIT compile excluded
    interrupted: bool = False
    state: dict[str, object] = field(default_factory=dict)
    photons: int = 0

    @property
    def primal(self) -> np.ndarray:
        return self.images["primal"]

    @property
    def gx(self) -> np.ndarray | None:
        return self.images.get("gx")

    @property
    def gy(self) -> np.ndarray | None:
        return self.images.get("gy")

    def variance(self, name: str = "primal") -> np.ndarray:
        """Per-pixel variance of the estimate ``images[name]``, from the two halves.

        With independent half means A, B (each over half the samples) the full mean is (A + B) / 2 and
        an unbiased estimate of its variance is (A - B)^2 / 4.
        """
        a, b = self.halves[name]
        return 0.25 * (a - b) ** 2

    def buffers(self) -> dict[str, np.ndarray]:
        """Every buffer for ``--buffers DIR``: images, halves (``<name>_a``/``<name>_b``), variances,
        and every array-valued ``state`` entry (a per-pixel radius or photon count map)."""
        out = dict(self.images)
        for name, (a, b) in self.halves.items():
            out[f"{name}_a"], out[f"{name}_b"] = a, b
            out[f"{name}_var"] = self.variance(name)
        for name, v in self.state.items():
            if isinstance(v, np.ndarray) and v.ndim >= 2:
                out[name] = v
        return out


@contextmanager
def _sigint_deferred():
    """Hold back Ctrl-C until the block is done, then raise it: the block's updates happen together.

    Only where Python raises ``KeyboardInterrupt`` itself (the main thread, the default handler);
    elsewhere (a worker thread, a handler someone else installed) the block runs as it is."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    caught = []
    signal.signal(signal.SIGINT, lambda *_: caught.append(True))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if caught:
        raise KeyboardInterrupt


class ProgressiveIntegrator:
    """Base class: the pass loop, timings, NaN/Inf guards and Ctrl-C safety.

    Subclasses set ``name``, choose ``combine`` (:class:`MeanOfPasses` by default, or
    :class:`LatestEstimate`) and implement :meth:`render_pass` and usually :meth:`compile`, which
    runs the numba kernels once on a tiny problem so compile time is measured apart.
    """

    name = "abstract"
    combine = MeanOfPasses

    def __init__(self, scene, *, seed: int = 0, spp_per_pass: int = 1):
        self.scene = scene
        self.seed = int(seed)
        self.spp_per_pass = int(spp_per_pass)
        self._combined = self.combine()
        self._compile_s: float | None = None
        self._passes = 0
        self._elapsed = 0.0

    # -- to be implemented -------------------------------------------------------------------------
    def render_pass(self, pass_index: int) -> PassResult:   # pragma: no cover - abstract
        """Render pass ``pass_index`` (0, 1, ...) and return its :class:`~gdlearn.integrators.base.PassResult`;
        every estimator implements this, :meth:`~gdlearn.integrators.base.ProgressiveIntegrator.step`
        folds the result into the frame."""
        raise NotImplementedError

    def compile(self) -> float:
        """Warm the JIT; return the seconds it took. The default renders nothing."""
        return 0.0

    # -- progressive driver ------------------------------------------------------------------------
    def warmup(self) -> float:
        """Compile once (:meth:`compile`); every later call returns the first call's seconds."""
        if self._compile_s is None:
            self._compile_s = float(self.compile())
        return self._compile_s

    def step(self) -> Frame:
        """Render one more pass and return the updated frame."""
        t0 = time.perf_counter()
        res = self.render_pass(self._passes)       # Ctrl-C in here drops this pass, and only it
        wall = time.perf_counter() - t0
        with _sigint_deferred():       # sums, sample counts and passes move together: a frame is whole
            self._combined.add(res, self._passes)
            self._elapsed += wall
            self._passes += 1
        return self.frame()

    def frames(self) -> Iterator[Frame]:
        """Endless progressive rendering: one frame per pass."""
        while True:
            yield self.step()

    def frame(self, interrupted: bool = False) -> Frame:
        c = self._combined
        images, halves = c.images_and_halves()
        timings = {} if self._compile_s is None else {"compile": self._compile_s}
        timings.update(c.timings)
        return Frame(self._passes, c.spp, images, halves, timings, dict(c.stats), self._elapsed, interrupted,
                     dict(c.state), c.photons)


def _done(frame: Frame, spp, seconds, passes, photons) -> bool:
    return ((spp is not None and frame.spp >= spp) or (seconds is not None and frame.elapsed >= seconds)
            or (passes is not None and frame.passes >= passes) or (photons is not None and frame.photons >= photons))


def render(integrator: ProgressiveIntegrator, spp: int | None = None, seconds: float | None = None,
           progress: bool = False, *, passes: int | None = None, photons: int | None = None) -> Frame:
    """Run ``integrator`` until ``spp`` samples per pixel, ``seconds`` of wall time, ``passes`` passes
    or ``photons`` light paths, whichever comes first (at least one pass; with no budget, the scene's
    spp). JIT compilation happens first and is not counted. Ctrl-C stops early and returns what was
    accumulated, with ``frame.interrupted`` set; before the first pass was accumulated there is
    nothing to return, and the ``KeyboardInterrupt`` goes on to the caller."""
    if spp is None and seconds is None and passes is None and photons is None:
        spp = getattr(integrator.scene.sensor, "spp", 4)
    integrator.warmup()
    bar = None
    if progress:
        from tqdm.auto import tqdm
        if spp is not None:
            bar = tqdm(total=spp, unit="spp", disable=None)
        else:
            bar = tqdm(total=passes, unit="pass", disable=None)
    frame = integrator.frame()
    try:
        while True:
            frame = integrator.step()
            if bar is not None:
                bar.update(integrator.spp_per_pass if spp is not None else 1)
                if frame.photons:
                    bar.set_postfix(photons=f"{frame.photons:.3g}", refresh=False)
            if _done(frame, spp, seconds, passes, photons):
                break
    except KeyboardInterrupt:
        frame = integrator.frame(interrupted=True)
        if frame.passes == 0:          # an empty frame has no images: not a result to hand back
            raise
    finally:
        if bar is not None:
            bar.close()
    return frame


__all__ = ["PassResult", "Frame", "ProgressiveIntegrator", "MeanOfPasses", "LatestEstimate", "render"]
