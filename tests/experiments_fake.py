"""A tiny deterministic fake integrator for the experiments tests (no renderer needed).

Each pass returns the known analytic image ``truth(h, w)`` plus Gaussian noise of standard deviation
``SIGMA`` per sample (seeded by (seed, pass), so runs are reproducible); ``FakeGradient`` also returns
the exact forward differences plus noise of ``SIGMA_G``. A pass sleeps ``PASS_SECONDS`` so that time
budgets translate into a predictable number of passes.
"""
import time

import numpy as np

from gdlearn.integrators.base import PassResult, ProgressiveIntegrator

SIGMA = 0.5
SIGMA_G = 0.05
PASS_SECONDS = 0.002


class VirtualClock:
    """A clock that moves only when someone sleeps: patched over ``time.perf_counter`` and
    ``time.sleep`` (the ``clock`` fixture of test_experiments_progressive), it makes the time-budget
    tests exact -- a fake pass takes PASS_SECONDS of virtual time whatever the machine's load."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def truth(h=6, w=8):
    y, x = np.mgrid[0:h, 0:w].astype(float)
    base = 0.1 + 0.05 * x + 0.1 * y
    return np.stack([base, 2 * base, 0.5 * base], axis=-1)


class FakePrimal(ProgressiveIntegrator):
    name = "fake-pt"

    def __init__(self, scene=None, *, seed=0, spp_per_pass=1, h=6, w=8):
        super().__init__(scene, seed=seed, spp_per_pass=spp_per_pass)
        self.truth = truth(h, w)

    def compile(self):
        return 0.01            # pretend the JIT took 10 ms (must be kept apart from pass time)

    def _noise(self, rng, sigma):
        return rng.normal(0.0, sigma / np.sqrt(self.spp_per_pass), self.truth.shape)

    def render_pass(self, i):
        time.sleep(PASS_SECONDS)
        rng = np.random.default_rng([self.seed, i])
        return PassResult({"primal": self.truth + self._noise(rng, SIGMA)}, self.spp_per_pass,
                          timings={"trace": PASS_SECONDS}, stats={"paths": self.truth[..., 0].size})


class FakeGradient(FakePrimal):
    name = "fake-gpt"

    def render_pass(self, i):
        time.sleep(PASS_SECONDS)
        rng = np.random.default_rng([self.seed, i])
        t = self.truth
        gx = np.zeros_like(t)
        gy = np.zeros_like(t)
        gx[:, :-1] = t[:, 1:] - t[:, :-1]
        gy[:-1] = t[1:] - t[:-1]
        imgs = {"primal": t + self._noise(rng, SIGMA), "gx": gx + self._noise(rng, SIGMA_G),
                "gy": gy + self._noise(rng, SIGMA_G)}
        return PassResult(imgs, self.spp_per_pass,
                          timings={"trace": PASS_SECONDS / 2, "shift": PASS_SECONDS / 2})


def fake_solver(frame):
    """A stand-in reconstruction (no dependency on gdlearn.reconstruct): each pixel but the first
    column averages its primal value with the left neighbour's value plus the gradient between them."""
    p, gx = frame.primal, frame.gx
    out = p.copy()
    out[:, 1:] = 0.5 * (p[:, 1:] + p[:, :-1] + gx[:, :-1])
    return out
