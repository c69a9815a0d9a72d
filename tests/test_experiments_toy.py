"""The toy estimators used by the book: closed-form truth vs quadrature, unbiased estimates."""
import numpy as np
import pytest

from gdlearn.teaching.toy import ToyGradient, ToyPrimal, ToyScene
from gdlearn.integrators.base import render


def test_truth_matches_midpoint_quadrature():
    sc = ToyScene(12, 8)
    n = 200                                             # midpoint rule, n x n points per pixel
    u = (np.arange(n) + 0.5) / n
    ys, xs = np.mgrid[0:sc.height, 0:sc.width]
    x = xs[..., None, None] + u[None, None, None, :]
    y = ys[..., None, None] + u[None, None, :, None]
    quad = sc.f(x, y).mean(axis=(2, 3))
    # Smooth parts converge as 1/n^2; a discontinuity crossing a pixel is off by at most
    # jump * (1/n) per edge: the light (40 * 0.9 = 36) has 4 edges -> 4 * 36 / 200 = 0.72.
    err = np.abs(quad - sc.truth())
    assert err.max() <= 4 * 36 / n
    smooth = err[..., 0] < 1e-3                          # most pixels: exact to quadrature error
    assert smooth.mean() > 0.8


@pytest.mark.parametrize("cls", [ToyPrimal, ToyGradient])
def test_estimates_are_unbiased(cls):
    sc = ToyScene(12, 8)
    frame = render(cls(sc, seed=4, spp_per_pass=64), spp=2048)
    t = sc.truth()
    se = np.sqrt(frame.variance()) + 1e-12               # per-pixel standard error from the halves
    z = (frame.primal - t) / se
    # 288 z-scores; half-buffer standard errors have 1 degree of freedom (heavy tails), so test
    # the pooled mean error against its pooled standard error instead of each pixel: k = 4.
    pooled = (frame.primal - t).sum() / np.sqrt(frame.variance().sum())
    assert abs(pooled) < 4
    assert np.isfinite(z).all()
    if cls is ToyGradient:
        gx = np.zeros_like(t)
        gx[:, :-1] = t[:, 1:] - t[:, :-1]
        pooled_g = (frame.gx - gx).sum() / np.sqrt(frame.variance("gx").sum() + 1e-30)
        assert abs(pooled_g) < 4
        # the point of gradients: away from edges they are far less noisy than the pixels
        assert np.median(frame.variance("gx")) < 0.1 * np.median(frame.variance())
