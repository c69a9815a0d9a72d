"""How an estimator's passes combine into a frame: the estimator's choice.

* :class:`MeanOfPasses` -- every pass is an independent estimate of the image (pt, gpt-replay, gpt;
  the memoryless progressive photon estimators of Knaus & Zwicker 2011, whose pass at radius r_i
  is an independent estimate of the image blurred by r_i). The frame is the spp-weighted mean. The
  two half-buffers the weighted reconstructions need come from the passes alternating between two
  sums -- or, when a pass makes its own two independent halves (``PassResult.halves``, e.g. two
  photon sets at the same radius inside one pass), from those, so that a radius schedule does not
  give the halves different biases.
* :class:`LatestEstimate` -- the estimator keeps per-pixel state across passes and each pass
  returns its current full estimate (SPPM's photon count N, radius R and flux tau per gather point,
  Hachisuka & Jensen 2009): the frame is the latest pass's images and halves.

Both count the samples and photons, sum the timings and counters, keep the last value of every
``state`` entry (radius, alpha, photons emitted: not summed), and drop non-finite pixels, counting
them: NaN or Inf never reach a frame.
"""
from __future__ import annotations

import numpy as np


def _finite(img, stats: dict) -> np.ndarray:
    img = np.asarray(img, dtype=np.float64)
    bad = ~np.isfinite(img)
    if bad.any():              # a guard upstream missed: count it, never let it through
        stats["nonfinite_pixels"] = stats.get("nonfinite_pixels", 0) + int(bad.sum())
        img = np.where(bad, 0.0, img)
    return img


class _Combine:
    def __init__(self):
        self.spp = 0
        self.photons = 0
        self.timings: dict[str, float] = {}
        self.stats: dict[str, int] = {}
        self.state: dict[str, object] = {}

    def _bookkeeping(self, res) -> None:
        self.spp += res.spp
        self.photons += int(res.photons)
        for k, v in res.timings.items():
            self.timings[k] = self.timings.get(k, 0.0) + v
        for k, v in res.stats.items():
            self.stats[k] = self.stats.get(k, 0) + int(v)
        self.state.update(res.state)


class MeanOfPasses(_Combine):
    """The spp-weighted mean of independent passes, with two half sums (see the module docstring)."""

    def __init__(self):
        super().__init__()
        self._sums: dict[str, list[np.ndarray]] = {}
        self._counts = [0, 0]            # samples per pixel in half A and half B

    def add(self, res, pass_index: int) -> None:
        if res.halves:
            for name, (a, b) in res.halves.items():
                sums = self._sums.setdefault(name, [None, None])
                for h, img in ((0, a), (1, b)):
                    img = _finite(img, self.stats) * res.spp
                    sums[h] = img if sums[h] is None else sums[h] + img
            self._counts[0] += res.spp
            self._counts[1] += res.spp
        else:
            h = pass_index % 2         # passes alternate between the two independent halves
            for name, img in res.images.items():
                img = _finite(img, self.stats)
                sums = self._sums.setdefault(name, [np.zeros_like(img), np.zeros_like(img)])
                sums[h] += img * res.spp
            self._counts[h] += res.spp
        self._bookkeeping(res)

    def images_and_halves(self):
        na, nb = self._counts
        n = max(na + nb, 1)
        images, halves = {}, {}
        for name, (a, b) in self._sums.items():
            images[name] = (a + b) / n
            # Before the second pass exists, both halves are the same single estimate.
            halves[name] = (a / max(na, 1), b / nb if nb else a / max(na, 1))
        return images, halves


class LatestEstimate(_Combine):
    """The estimator's own running estimate: the latest pass's images and halves."""

    def __init__(self):
        super().__init__()
        self._images: dict[str, np.ndarray] = {}
        self._halves: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def add(self, res, pass_index: int) -> None:
        self._images = {name: _finite(img, self.stats) for name, img in res.images.items()}
        halves = res.halves or {}
        self._halves = {name: (_finite(a, self.stats), _finite(b, self.stats)) for name, (a, b) in halves.items()}
        for name, img in self._images.items():
            self._halves.setdefault(name, (img, img))
        self._bookkeeping(res)

    def images_and_halves(self):
        return dict(self._images), dict(self._halves)
