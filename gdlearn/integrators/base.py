"""One protocol for every estimator: progressive passes that yield :class:`Frame` objects.

Every integrator in gdlearn -- the primal path tracer, the gradient-domain path tracers, and later
the photon-density estimators -- renders *progressively*: each call of ``render_pass`` adds one
independent pass of samples, and the shared :class:`ProgressiveIntegrator` accumulates it. A frame
carries everything the rest of the road needs:

* ``primal``: the accumulated primal image (H x W x 3, float64, linear RGB);
* ``gx`` / ``gy``: forward-difference gradient images, ``gx[y, x] ~ I[y, x+1] - I[y, x]`` and
  ``gy[y, x] ~ I[y+1, x] - I[y, x]`` (None for primal-only estimators);
* two independent half-buffers of every image (passes alternate between them), from which the
  weighted reconstructions estimate per-pixel variances (:meth:`Frame.variance`);
* shift statistics (success / failure / null / mixed counts) and non-finite-sample counts;
* the wall time of each stage (``trace``, ``shift``, ``gather``, ...), with JIT compilation kept
  apart in ``compile``, so the experiments module can compare estimators at equal time.

An integrator subclass implements only :meth:`ProgressiveIntegrator.render_pass`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

#: Names of the image buffers an integrator may produce, in the order they are written to disk.
BUFFER_NAMES = ("primal", "gx", "gy")


@dataclass
class PassResult:
    """What one pass returns: per-pixel *means over this pass's samples* for each buffer it produces,
    the pass's samples per pixel, its stage timings (seconds) and counters (shift statistics etc.)."""
    images: dict[str, np.ndarray]
    spp: int
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, int] = field(default_factory=dict)


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
        """Per-pixel variance of the accumulated estimate ``images[name]``, from the two halves.

        With independent half means A, B (each over half the samples) the full mean is (A + B) / 2 and
        an unbiased estimate of its variance is (A - B)^2 / 4.
        """
        a, b = self.halves[name]
        return 0.25 * (a - b) ** 2

    def buffers(self) -> dict[str, np.ndarray]:
        """Every buffer for ``--buffers DIR``: images, halves (``<name>_a``/``<name>_b``), variances."""
        out = dict(self.images)
        for name, (a, b) in self.halves.items():
            out[f"{name}_a"], out[f"{name}_b"] = a, b
            out[f"{name}_var"] = self.variance(name)
        return out


class ProgressiveIntegrator:
    """Base class: accumulation, half-buffers, timings, NaN/Inf guards and Ctrl-C safety.

    Subclasses set ``name`` and implement :meth:`render_pass` (and usually :meth:`compile`, which
    runs the numba kernels once on a tiny problem so compile time is measured apart).
    """

    name = "abstract"

    def __init__(self, scene, *, seed: int = 0, spp_per_pass: int = 1):
        self.scene = scene
        self.seed = int(seed)
        self.spp_per_pass = int(spp_per_pass)
        self._sums: dict[str, list[np.ndarray]] = {}
        self._counts = [0, 0]            # samples per pixel in half A and half B
        self._timings: dict[str, float] = {}
        self._stats: dict[str, int] = {}
        self._passes = 0
        self._elapsed = 0.0

    # -- to be implemented -------------------------------------------------------------------------
    def render_pass(self, pass_index: int) -> PassResult:   # pragma: no cover - abstract
        raise NotImplementedError

    def compile(self) -> float:
        """Warm the JIT; return the seconds it took. The default renders nothing."""
        return 0.0

    # -- progressive driver ------------------------------------------------------------------------
    def warmup(self) -> float:
        t = self.compile()
        self._timings["compile"] = self._timings.get("compile", 0.0) + t
        return t

    def step(self) -> Frame:
        """Render one more pass and return the updated frame."""
        t0 = time.perf_counter()
        res = self.render_pass(self._passes)
        wall = time.perf_counter() - t0
        self._accumulate(res)
        self._elapsed += wall
        self._passes += 1
        return self.frame()

    def frames(self) -> Iterator[Frame]:
        """Endless progressive rendering: one frame per pass."""
        while True:
            yield self.step()

    def _accumulate(self, res: PassResult) -> None:
        h = self._passes % 2           # passes alternate between the two independent halves
        for name, img in res.images.items():
            img = np.asarray(img, dtype=np.float64)
            bad = ~np.isfinite(img)
            if bad.any():              # a guard upstream missed: count it, never let it through
                self._stats["nonfinite_pixels"] = self._stats.get("nonfinite_pixels", 0) + int(bad.sum())
                img = np.where(bad, 0.0, img)
            sums = self._sums.setdefault(name, [np.zeros_like(img), np.zeros_like(img)])
            sums[h] += img * res.spp
        self._counts[h] += res.spp
        for k, v in res.timings.items():
            self._timings[k] = self._timings.get(k, 0.0) + v
        for k, v in res.stats.items():
            self._stats[k] = self._stats.get(k, 0) + int(v)

    def frame(self, interrupted: bool = False) -> Frame:
        na, nb = self._counts
        n = max(na + nb, 1)
        images, halves = {}, {}
        for name, (a, b) in self._sums.items():
            images[name] = (a + b) / n
            # Before the second pass exists, both halves are the same single estimate.
            halves[name] = (a / max(na, 1), b / nb if nb else a / max(na, 1))
        return Frame(self._passes, na + nb, images, halves, dict(self._timings), dict(self._stats),
                     self._elapsed, interrupted)


def render(integrator: ProgressiveIntegrator, spp: int | None = None, seconds: float | None = None,
           progress: bool = False) -> Frame:
    """Run ``integrator`` until ``spp`` samples per pixel or ``seconds`` of wall time (whichever comes
    first; at least one pass). JIT compilation happens first and is not counted. Ctrl-C stops early
    and returns what was accumulated, with ``frame.interrupted`` set."""
    if spp is None and seconds is None:
        spp = getattr(integrator.scene.sensor, "spp", 4)
    integrator.warmup()
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=spp, unit="spp", disable=None) if spp else tqdm(unit="pass", disable=None)
    frame = integrator.frame()
    try:
        while True:
            frame = integrator.step()
            if bar is not None:
                bar.update(integrator.spp_per_pass if spp else 1)
            if spp is not None and frame.spp >= spp:
                break
            if seconds is not None and frame.elapsed >= seconds:
                break
    except KeyboardInterrupt:
        frame = integrator.frame(interrupted=True)
    finally:
        if bar is not None:
            bar.close()
    return frame
