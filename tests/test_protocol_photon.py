"""The integrator protocol carries a photon estimator end to end: a toy photon-pass estimator.

The toy "scene" is the unit square, the film a W x H grid over it, and the light emits photons
uniformly over the square with total power 1: the exact irradiance is 1 everywhere, and a disc
kernel of radius r at a pixel centre at least r from the border estimates it without bias. Each
pass traces photons with the light-path key space (``rand(seed, LIGHT_KEY0 + j, pass, dim)``),
builds nothing, gathers by brute force and shrinks the radius -- the skeleton of
:class:`gdlearn.integrators.photon_base.PhotonPassIntegrator`, both ways of combining passes, the
state that is not summed, the in-pass halves, and the budgets in passes and photons.
"""
import math

import numpy as np
import pytest
from numba import njit, prange

from gdlearn.integrators.base import Frame, PassResult, render
from gdlearn.integrators.combine import LatestEstimate, MeanOfPasses
from gdlearn.integrators.photon_base import PhotonPassIntegrator
from gdlearn.kernels.rng import LIGHT_KEY0, rand


@njit(cache=True, parallel=True)
def _trace(seed, pass_index, j0, n, out):
    for j in prange(n):
        out[j, 0] = rand(seed, LIGHT_KEY0 + j0 + j, pass_index, 0)
        out[j, 1] = rand(seed, LIGHT_KEY0 + j0 + j, pass_index, 1)


class _Film:
    width, height = 8, 6


class _Scene:
    class sensor:
        film = _Film
        spp = 1


class ToyPhotons(PhotonPassIntegrator):
    """Irradiance of a uniform unit-power light on the unit square, by disc-kernel density estimation."""

    name = "toy-photons"

    def __init__(self, *, seed=0, photons_per_pass=4000, radius=0.1, alpha=0.7, combine=MeanOfPasses):
        self.combine = combine
        super().__init__(_Scene, seed=seed, photons_per_pass=photons_per_pass)
        self.radius, self.alpha = radius, alpha
        w, h = _Film.width, _Film.height
        # pixel centres inside [r, 1 - r]^2 so the disc never leaves the square
        self.cx = 0.25 + 0.5 * (np.arange(w) + 0.5) / w
        self.cy = 0.25 + 0.5 * (np.arange(h) + 0.5) / h

    def trace_photons(self, i):
        n = self.photons_per_pass
        pts = np.empty((2 * n, 2))
        _trace(self.seed, i, 0, 2 * n, pts)       # half A: j in [0, n), half B: [n, 2n)
        return pts

    def _density(self, pts):
        d2 = (self.cx[None, :, None] - pts[None, None, :, 0]) ** 2 + (self.cy[:, None, None] - pts[None, None, :, 1]) ** 2
        inside = (d2 < self.radius ** 2).sum(axis=2)
        # each photon carries power 1 / (light paths emitted); the kernel normalises by pi r^2
        est = inside / (len(pts) * math.pi * self.radius ** 2)
        return np.repeat(est[:, :, None], 3, axis=2)

    def gather(self, pts, i):
        n = self.photons_per_pass
        a, b = self._density(pts[:n]), self._density(pts[n:])
        return PassResult(images={"primal": 0.5 * (a + b)}, spp=1, halves={"primal": (a, b)},
                          stats={"gathered": 1})

    def update_radius(self, i):
        # Knaus & Zwicker 2011's global schedule: r_{i+1}^2 = r_i^2 (i + alpha) / (i + 1)
        self.radius *= math.sqrt((i + 1 + self.alpha) / (i + 2))

    def pass_state(self):
        return {"radius": self.radius, "alpha": self.alpha}

    def emitted(self, pts):
        return len(pts)


def test_a_photon_pass_estimator_runs_end_to_end_and_is_unbiased():
    integ = ToyPhotons(seed=4)
    f = render(integ, passes=12)
    assert isinstance(f, Frame) and f.passes == 12 and f.photons == 12 * 8000
    # the state is the last pass's, not a sum: the radius after 12 reductions
    r = 0.1
    for i in range(12):
        r *= math.sqrt((i + 1 + 0.7) / (i + 2))
    assert f.state["radius"] == pytest.approx(r, rel=1e-12) and f.state["alpha"] == 0.7
    assert f.stats["gathered"] == 12                       # counters are summed
    assert {"photons", "build", "gather", "update"} <= set(f.timings)
    # unbiased at every radius: the mean over 48 pixels x 12 passes is 1 within 4 standard errors
    # (the half difference gives each pixel's variance, independent of the mean)
    img = f.primal[..., 0]
    se = math.sqrt(f.variance()[..., 0].mean() / img.size)
    assert abs(img.mean() - 1.0) < 4 * se, (img.mean(), se)
    # halves come from inside the passes (equal radius), not from alternating passes
    a, b = f.halves["primal"]
    np.testing.assert_allclose(0.5 * (a + b), f.primal, rtol=1e-12)


def test_a_wrong_normalisation_is_caught_by_the_same_check():
    class Wrong(ToyPhotons):
        def _density(self, pts):
            return super()._density(pts) * (len(pts) / (len(pts) - 100))   # normalised by too few paths

    f = render(Wrong(seed=4), passes=12)
    img = f.primal[..., 0]
    se = math.sqrt(f.variance()[..., 0].mean() / img.size)
    assert abs(img.mean() - 1.0) > 4 * se


def test_latest_estimate_keeps_the_estimators_own_state():
    class Recording(ToyPhotons):
        def gather(self, pts, i):
            self.last = super().gather(pts, i)
            return self.last

    integ = Recording(seed=1, combine=LatestEstimate)
    f = render(integ, photons=3 * 8000)                  # a budget in photons: three passes
    assert f.passes == 3 and f.spp == 3
    # the frame is the last pass's estimate and halves, not a mean over passes
    np.testing.assert_array_equal(f.primal, integ.last.images["primal"])
    for got, want in zip(f.halves["primal"], integ.last.halves["primal"]):
        np.testing.assert_array_equal(got, want)


def test_light_paths_do_not_depend_on_the_thread_count():
    import numba
    a, b = np.empty((5000, 2)), np.empty((5000, 2))
    old = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        _trace(9, 3, 0, 5000, a)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        _trace(9, 3, 0, 5000, b)
    finally:
        numba.set_num_threads(old)
    assert np.array_equal(a, b) and len(np.unique(a[:, 0])) == 5000


def test_warmup_compiles_once_and_reports_the_first_time():
    class Counting(ToyPhotons):
        calls = 0

        def compile(self):
            Counting.calls += 1
            return 1.5

    integ = Counting()
    assert integ.warmup() == 1.5 and integ.warmup() == 1.5 and Counting.calls == 1
    f = render(integ, passes=1)
    assert Counting.calls == 1 and f.timings["compile"] == 1.5
