"""Compare two Monte Carlo images with a tolerance calibrated from their own noise.

Two renderers that solve the same rendering equation without bias converge to the same image; at a
finite sample count they differ by noise whose size each estimate knows (its standard error). The
comparison therefore asks, block by block, whether the difference is explainable by that noise:

1. Both images come with a per-pixel mean ``m``, the variance of that mean ``v`` (squared standard
   error) and the degrees of freedom ``d`` of ``v`` (K independent renders: ``d = K - 1``; the two
   half-buffers of a :class:`~gdlearn.integrators.base.Frame`: ``d = 1``).
2. Pixels are averaged over ``block x block`` tiles: pixels are independent Monte Carlo estimates,
   so the block mean's variance is ``sum(v) / n^2`` and its degrees of freedom follow from
   Welch-Satterthwaite, ``(sum v)^2 / sum(v^2 / d)``.
3. Per block and channel, ``z = (m_test - m_ref) / sqrt(v_test + v_ref)`` follows Student's t with
   the Welch-Satterthwaite degrees of freedom of the sum (Welch's unequal-variance t-test).
4. With m block-channel tests (plus the 3 channels of the whole-image mean), every test gets the
   Bonferroni share alpha / m of the family-wise false-alarm probability alpha: the bound is
   ``|z| < t.isf(alpha / (2 m), dof)`` (about 4.6 for m = 195, alpha = 1e-3, many dof).
5. Beyond the noise test, the image mean must agree to ``rel_bound`` (relative, per channel): a
   small bias that is statistically significant only at very high sample counts is still caught
   at the size we care about, and an underpowered comparison cannot pass silently on a mean
   that is far off.

A stored reference loses precision to float32 (relative 6e-8); a variance floor of
``(FLOAT_EPS * |m|)^2`` keeps noise-free pixels (e.g. an emitter seen directly) from turning that
rounding into an infinite z, while a real difference there is still infinitely significant.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Relative precision assumed for stored means (float32 storage plus summation rounding).
FLOAT_EPS = 1e-6


@dataclass
class ImageStats:
    """A Monte Carlo image estimate: per-pixel ``mean``, ``var`` (variance *of the mean*, i.e. the
    squared standard error) and ``dof`` (degrees of freedom of ``var``), all H x W x 3."""
    mean: np.ndarray
    var: np.ndarray
    dof: np.ndarray

    @classmethod
    def from_samples(cls, images) -> "ImageStats":
        """From K >= 2 independent renders (same spp each): mean, var = s^2 / K, dof = K - 1."""
        a = np.asarray(images, dtype=np.float64)
        k = a.shape[0]
        if k < 2:
            raise ValueError("ImageStats.from_samples needs at least 2 independent images")
        return cls(a.mean(0), a.var(0, ddof=1) / k, np.full(a.shape[1:], k - 1.0))

    @classmethod
    def from_mean_stderr(cls, mean, stderr, k: int) -> "ImageStats":
        """From a stored mean and per-pixel standard error estimated over ``k`` independent renders."""
        mean = np.asarray(mean, dtype=np.float64)
        return cls(mean, np.asarray(stderr, dtype=np.float64) ** 2, np.full(mean.shape, k - 1.0))

    @classmethod
    def from_frame(cls, frame, name: str = "primal") -> "ImageStats":
        """From one progressive Frame: its two independent half-buffers give var = (A - B)^2 / 4 with
        one degree of freedom per pixel (:meth:`Frame.variance`)."""
        mean = np.asarray(frame.images[name], dtype=np.float64)
        return cls(mean, np.asarray(frame.variance(name), dtype=np.float64), np.ones(mean.shape))


def _blocks(a: np.ndarray, b: int, reduce=np.sum) -> np.ndarray:
    h, w, c = a.shape
    if h % b or w % b:
        raise ValueError(f"image {h}x{w} is not a whole number of {b}x{b} blocks; choose block "
                         f"size dividing both (e.g. 4 or 8 for 32x32)")
    return reduce(a.reshape(h // b, b, w // b, b, c), axis=(1, 3))


def _satterthwaite(v_sum: np.ndarray, v2_over_d_sum: np.ndarray) -> np.ndarray:
    """Welch-Satterthwaite degrees of freedom of a sum of variance estimates: (sum v)^2 / sum(v^2/d)
    (infinite when the sum is exactly zero: a noise-free value)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        dof = v_sum ** 2 / v2_over_d_sum
    return np.where(v_sum > 0, dof, np.inf)


def block_stats(s: ImageStats, block: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block means, their variances and Welch-Satterthwaite degrees of freedom (By x Bx x 3)."""
    n = block * block
    v_sum = _blocks(s.var, block)
    dof = _satterthwaite(v_sum, _blocks(np.where(s.var > 0, s.var ** 2 / s.dof, 0.0), block))
    return _blocks(s.mean, block) / n, v_sum / n ** 2, dof


def _welch(dm, va, da, vb, db, scale):
    """z, its Student-t degrees of freedom, for differences ``dm`` with variances va, vb."""
    v = va + vb + (FLOAT_EPS * scale) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(v > 0, dm / np.sqrt(v), np.where(dm == 0, 0.0, np.inf * np.sign(dm)))
        terms = np.where(va > 0, va ** 2 / da, 0.0) + np.where(vb > 0, vb ** 2 / db, 0.0)
        dof = np.where(terms > 0, (va + vb) ** 2 / terms, np.inf)
    return z, np.maximum(dof, 1.0)


@dataclass
class Comparison:
    """Result of :func:`compare`. ``z``/``bound``/``ratio`` are By x Bx x 3 (block rows, block
    columns, channel); ``rel_diff``/``z_mean`` are per channel for the whole-image mean."""
    block: int
    z: np.ndarray
    bound: np.ndarray
    ratio: np.ndarray
    rel_diff: np.ndarray
    z_mean: np.ndarray
    bound_mean: np.ndarray
    rel_bound: float
    alpha: float

    @property
    def blocks_ok(self) -> bool:
        return bool(np.all(np.abs(self.z) < self.bound))

    @property
    def mean_ok(self) -> bool:
        return bool(np.all(np.abs(self.z_mean) < self.bound_mean)
                    and np.all(np.abs(self.rel_diff) < self.rel_bound))

    @property
    def ok(self) -> bool:
        return self.blocks_ok and self.mean_ok

    @property
    def mean_resolved(self) -> bool:
        """Is ``rel_bound`` at least 3 standard errors of the relative mean difference wide in every
        channel? If not, a mean beyond the bound may be noise alone (a random scene's mean can rest
        on a few bright paths): the comparison needs more samples before it means anything."""
        with np.errstate(divide="ignore", invalid="ignore"):
            se = np.where(self.z_mean != 0.0, np.abs(self.rel_diff / self.z_mean), 0.0)
        return bool(np.all(self.rel_bound >= 3.0 * se))

    @property
    def inconclusive(self) -> bool:
        """Failed on the image mean alone, which is not resolved (:attr:`mean_resolved`)."""
        return (not self.ok) and self.blocks_ok and bool(np.all(np.abs(self.z_mean) < self.bound_mean)) \
            and not self.mean_resolved

    @property
    def mean_z2(self) -> float:
        """Mean z^2 over the finite blocks: ~1 when both images agree and the noise is calibrated."""
        z = self.z[np.isfinite(self.z)]
        return float(np.mean(z ** 2)) if z.size else 0.0

    def worst(self) -> dict:
        """The block with the largest |z| / bound: pixel region, channel, z, bound, ratio."""
        r = np.abs(self.z) / self.bound
        by, bx, c = np.unravel_index(int(np.nanargmax(r)), r.shape)
        b = self.block
        return dict(rows=(by * b, by * b + b), cols=(bx * b, bx * b + b), channel="RGB"[c],
                    z=float(self.z[by, bx, c]), bound=float(self.bound[by, bx, c]),
                    ratio=float(self.ratio[by, bx, c]))

    def summary(self) -> str:
        w = self.worst()
        n_bad = int(np.sum(np.abs(self.z) >= self.bound))
        verdict = "OK" if self.ok else ("INCONCLUSIVE" if self.inconclusive else "MISMATCH")
        return (f"{verdict}: {n_bad}/{self.z.size} blocks beyond the bound; "
                f"worst block rows {w['rows'][0]}:{w['rows'][1]} cols {w['cols'][0]}:{w['cols'][1]} "
                f"channel {w['channel']}: z = {w['z']:+.2f} (bound {w['bound']:.2f}), "
                f"test/ref = {w['ratio']:.4f}; image mean test/ref - 1 = "
                f"{', '.join(f'{d:+.4f}' for d in self.rel_diff)} (bound {self.rel_bound}), "
                f"z = {', '.join(f'{z:+.2f}' for z in self.z_mean)}; mean z^2 = {self.mean_z2:.2f} "
                f"(~1 when calibrated; {self.block}x{self.block} blocks, alpha = {self.alpha:g})")


def compare(test: ImageStats, ref: ImageStats, block: int = 4, alpha: float = 1e-3,
            rel_bound: float = 0.03) -> Comparison:
    """Compare ``test`` against ``ref`` (see the module docstring for the statistics).

    block: tile size in pixels; alpha: family-wise false-alarm probability (Bonferroni over all
    block-channel tests and the 3 whole-image means); rel_bound: largest allowed relative difference
    of the whole-image mean per channel.
    """
    if test.mean.shape != ref.mean.shape:
        raise ValueError(f"image shapes differ: test {test.mean.shape} vs reference {ref.mean.shape}; "
                         "render both at the same resolution (the scene's `res` default)")
    mt, vt, dt = block_stats(test, block)
    mr, vr, dr = block_stats(ref, block)
    z, dof = _welch(mt - mr, vt, dt, vr, dr, np.maximum(np.abs(mt), np.abs(mr)))
    m = z.size + 3
    bound = stats.t.isf(alpha / (2 * m), dof)

    # Whole-image mean: the block means averaged again (every block has the same pixel count).
    nb = mt.shape[0] * mt.shape[1]
    gt, gr = mt.mean((0, 1)), mr.mean((0, 1))
    gvt, gvr = vt.sum((0, 1)) / nb ** 2, vr.sum((0, 1)) / nb ** 2
    gdt = _satterthwaite(vt.sum((0, 1)), np.where(vt > 0, vt ** 2 / dt, 0.0).sum((0, 1)))
    gdr = _satterthwaite(vr.sum((0, 1)), np.where(vr > 0, vr ** 2 / dr, 0.0).sum((0, 1)))
    z_mean, dof_mean = _welch(gt - gr, gvt, gdt, gvr, gdr, np.maximum(np.abs(gt), np.abs(gr)))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(gr > 0, gt / gr - 1.0, np.where(gt == 0, 0.0, np.inf))
        ratio = np.where(mr > 0, mt / mr, np.where(mt == 0, 1.0, np.inf))
    return Comparison(block, z, bound, ratio, rel, z_mean, stats.t.isf(alpha / (2 * m), dof_mean),
                      rel_bound, alpha)
