"""The skeleton every photon-density estimator's pass follows: trace -> build -> gather -> update.

A pass of SPPM, GPM, VPM, the beam radiance estimate, photon beams or planes (and their gradient
versions) has the same four stages (Hachisuka & Jensen 2009, Alg. 1; Jarosz et al. 2008 §4;
Gruson et al. 2018 §6):

1. ``trace_photons(i)``: light paths of pass i, kept as vertex records (:mod:`gdlearn.photons`);
2. ``build(photons)``: the acceleration structure the gather queries (a hash grid or kd-tree for
   points, a bounding-box hierarchy for discs, beams or planes), rebuilt every pass;
3. ``gather(accel, i)``: the camera side -- gather points or camera beams query the structure at
   the pass's radius -- returning a :class:`~gdlearn.integrators.base.PassResult`;
4. ``update_radius(i)``: the progressive radius reduction (per gather point, or a global schedule).

:meth:`PhotonPassIntegrator.render_pass` runs them in order and times each (``photons``, ``build``,
``gather``, ``update``), so equal-time studies see where a photon estimator spends its time.

Random numbers: light path j of pass i draws ``rand(seed, LIGHT_KEY0 + j, i, dim)``
(:data:`!gdlearn.kernels.rng.LIGHT_KEY0`): a key space disjoint from the pixels' ``y * W + x``, so
a photon map is a pure function of (scene, seed, pass) -- the same for 1 and 2 threads, and the
same photons for a gradient estimator's base and offset gather points. An estimator that needs two
independent halves inside one pass (for the weighted reconstructions, at equal radius) gives half
B the light paths j in [n, 2n).
"""
from __future__ import annotations

import time

from gdlearn.integrators.base import PassResult, ProgressiveIntegrator
from gdlearn.integrators.combine import LatestEstimate


class PhotonPassIntegrator(ProgressiveIntegrator):
    """Base class of the photon estimators; a subclass implements the four stages.

    ``combine`` defaults to :class:`~gdlearn.integrators.combine.LatestEstimate` (per-pixel state,
    SPPM); a memoryless estimator with a global radius schedule sets
    :class:`~gdlearn.integrators.combine.MeanOfPasses`. ``photons_per_pass`` light paths are emitted
    each pass; :meth:`pass_state` reports what is not summed (radius, alpha)."""

    combine = LatestEstimate

    def __init__(self, scene, *, seed: int = 0, spp_per_pass: int = 1, photons_per_pass: int = 100_000):
        super().__init__(scene, seed=seed, spp_per_pass=spp_per_pass)
        if int(photons_per_pass) < 1:
            raise ValueError(f"photons_per_pass={photons_per_pass!r}: a pass must emit at least one light path")
        self.photons_per_pass = int(photons_per_pass)

    # -- the four stages -----------------------------------------------------------------------------
    def trace_photons(self, pass_index: int):   # pragma: no cover - abstract
        raise NotImplementedError

    def build(self, photons):
        """The structure :meth:`gather` queries; the default hands the photons through."""
        return photons

    def gather(self, accel, pass_index: int) -> PassResult:   # pragma: no cover - abstract
        """The camera pass: estimate every pixel from the photons in ``accel`` (what :meth:`build`
        returned); each estimator implements this."""
        raise NotImplementedError

    def update_radius(self, pass_index: int) -> None:
        """Shrink the radius after pass ``pass_index`` (default: a fixed radius)."""

    def release(self, photons) -> None:
        """The pass is done with ``photons`` (default: nothing; a tracer may reuse their memory)."""

    def pass_state(self) -> dict:
        """Values reported in ``Frame.state`` after each pass (not summed; last value wins)."""
        return {}

    def emitted(self, photons) -> int:
        """Light paths emitted by a pass (the density estimate's normalisation)."""
        return self.photons_per_pass

    # -- the skeleton --------------------------------------------------------------------------------
    def render_pass(self, pass_index: int) -> PassResult:
        """One pass: trace photons, build, gather, update the radius, each stage timed."""
        t0 = time.perf_counter()
        photons = self.trace_photons(pass_index)
        t1 = time.perf_counter()
        accel = self.build(photons)
        t2 = time.perf_counter()
        res = self.gather(accel, pass_index)
        t3 = time.perf_counter()
        self.update_radius(pass_index)
        t4 = time.perf_counter()
        res.timings.update(photons=t1 - t0, build=t2 - t1, gather=t3 - t2, update=t4 - t3)
        res.photons = self.emitted(photons)
        self.release(photons)
        res.state = {**self.pass_state(), **res.state}
        return res
