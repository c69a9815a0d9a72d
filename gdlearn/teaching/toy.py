"""Toy estimators with an exactly known answer, for teaching and testing the experiment machinery.

A *toy scene* is an analytic image: the film function f(x, y) is a smooth colour ramp, a hard edge
and a small, very bright rectangle (a "light"), so the exact pixel values -- box-filtered integrals
of f over each pixel -- have closed forms (:meth:`ToyScene.truth`). Two Monte Carlo estimators
follow the integrator protocol (:mod:`gdlearn.integrators.base`):

* :class:`ToyPrimal` estimates each pixel with samples at uniform positions in the pixel, each
  multiplied by a random weight of mean 1 that stands in for the noise of path throughputs;
* :class:`ToyGradient` additionally estimates the forward differences gx, gy by evaluating the
  neighbour pixel with the *same* random numbers (the same sub-pixel offset and weight) -- the
  image-space analogue of random-sequence replay (Hua et al. 2019, §2.3). Where f is smooth the two
  samples nearly cancel, so the gradients have far less variance than the pixels, which is what
  gradient-domain reconstruction exploits (Hua et al. 2019, §2.2).

They cost real time (numpy work proportional to the samples), so equal-time comparisons between
them are honest, if not representative of light transport. The book's chapter "What accuracy
costs" (book/accuracy.md) uses them where an exact answer is needed.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gdlearn.integrators.base import PassResult, ProgressiveIntegrator

_COLOUR = np.array([0.9, 0.6, 0.35])     # ramp colour (R, G, B)
_LIGHT = 40.0                            # radiance of the bright rectangle: a high dynamic range


@dataclass(frozen=True)
class ToyScene:
    """An analytic film function over [0, width] x [0, height] (pixel units)."""
    width: int = 48
    height: int = 32
    name: str = "toy"
    weight_sigma: float = 1.0            # standard deviation of the per-sample weight (mean 1)

    def _geometry(self):
        w, h = float(self.width), float(self.height)
        edge = 0.62 * w                                   # vertical edge: x > edge gets +0.3
        light = (0.2 * w, 0.2 * w + max(2.0, 0.08 * w), 0.15 * h, 0.15 * h + max(2.0, 0.1 * h))
        return w, h, edge, light

    def f(self, x, y) -> np.ndarray:
        """The film function at points (x, y) (arrays of equal shape): shape + (3,)."""
        w, h, edge, (x0, x1, y0, y1) = self._geometry()
        ramp = 0.05 + 0.45 * (1.0 + np.sin(2 * np.pi * x / w)) * (y / h)
        v = ramp + 0.3 * (x > edge) + _LIGHT * ((x > x0) & (x < x1) & (y > y0) & (y < y1))
        return v[..., None] * _COLOUR

    def truth(self) -> np.ndarray:
        """Exact pixel values: the integral of f over each unit pixel square, H x W x 3."""
        w, h, edge, (x0, x1, y0, y1) = self._geometry()
        xs, ys = np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64)
        k = 2 * np.pi / w
        # integral over [i, i+1] of (1 + sin(k x)) dx, and of y / h over [j, j+1]
        sx = 1.0 + (np.cos(k * xs) - np.cos(k * (xs + 1))) / k
        sy = (ys + 0.5) / h
        ramp = 0.05 + 0.45 * sy[:, None] * sx[None, :]
        step = np.clip(xs + 1 - edge, 0.0, 1.0)
        ox = np.clip(np.minimum(xs + 1, x1) - np.maximum(xs, x0), 0.0, 1.0)
        oy = np.clip(np.minimum(ys + 1, y1) - np.maximum(ys, y0), 0.0, 1.0)
        v = ramp + 0.3 * step[None, :] + _LIGHT * oy[:, None] * ox[None, :]
        return v[..., None] * _COLOUR


def _weights(rng, shape, sigma):
    """Random sample weights of mean 1 and standard deviation ``sigma`` (a gamma distribution, so
    weights stay positive like path throughputs)."""
    k = 1.0 / (sigma * sigma)
    return rng.gamma(k, 1.0 / k, size=shape)


class ToyPrimal(ProgressiveIntegrator):
    """Primal Monte Carlo estimate of :meth:`ToyScene.truth` (see the module docstring)."""

    name = "toy-pt"

    def __init__(self, scene=None, *, seed: int = 0, spp_per_pass: int = 1):
        super().__init__(scene if isinstance(scene, ToyScene) else ToyScene(), seed=seed,
                         spp_per_pass=spp_per_pass)

    def compile(self) -> float:
        """Nothing is JIT-compiled, but numpy's first calls (random generator set-up, gamma
        sampler) cost milliseconds; one throw-away pass keeps that out of the measured curves."""
        t0 = time.perf_counter()
        self.render_pass(2 ** 40)         # a pass index no run reaches: its samples are unused
        return time.perf_counter() - t0

    def _samples(self, pass_index):
        sc = self.scene
        rng = np.random.default_rng([self.seed, pass_index])   # one stream per (seed, pass)
        shape = (self.spp_per_pass, sc.height, sc.width)
        u, v = rng.random(shape), rng.random(shape)
        wgt = _weights(rng, shape, sc.weight_sigma)[..., None]
        x = np.arange(sc.width)[None, None, :] + u
        y = np.arange(sc.height)[None, :, None] + v
        return x, y, wgt

    def render_pass(self, pass_index: int) -> PassResult:
        t0 = time.perf_counter()
        x, y, wgt = self._samples(pass_index)
        primal = (self.scene.f(x, y) * wgt).mean(axis=0)
        return PassResult({"primal": primal}, self.spp_per_pass,
                          timings={"trace": time.perf_counter() - t0})


class ToyGradient(ToyPrimal):
    """Primal plus replayed-offset gradient estimates gx, gy (zero on the last column / row, which
    have no neighbour)."""

    name = "toy-gpt"

    def render_pass(self, pass_index: int) -> PassResult:
        t0 = time.perf_counter()
        x, y, wgt = self._samples(pass_index)
        base = self.scene.f(x, y) * wgt
        t1 = time.perf_counter()
        # The same (u, v, weight) one pixel to the right / below: a shifted sample pair.
        gx = (self.scene.f(x + 1.0, y) * wgt - base).mean(axis=0)
        gy = (self.scene.f(x, y + 1.0) * wgt - base).mean(axis=0)
        gx[:, -1] = 0.0
        gy[-1, :] = 0.0
        t2 = time.perf_counter()
        return PassResult({"primal": base.mean(axis=0), "gx": gx, "gy": gy}, self.spp_per_pass,
                          timings={"trace": t1 - t0, "shift": t2 - t1})
