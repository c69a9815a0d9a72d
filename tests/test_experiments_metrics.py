"""relMSE and friends on inputs whose answer is worked out by hand (seed 000 §6, seed 001 §4.5)."""
import numpy as np
import pytest

from gdlearn.experiments import metrics as M


def test_relmse_per_channel_by_hand():
    ref = np.array([[[0.0, 1.0, 2.0]]])
    img = np.array([[[0.1, 1.0, 1.0]]])
    # channel terms: 0.01 / (0 + 0.001) = 10, 0, 1 / (4 + 0.001); averaged over the 3 channels
    expected = (10.0 + 0.0 + 1.0 / 4.001) / 3.0
    assert M.relmse(img, ref) == pytest.approx(expected, rel=1e-12)
    assert M.relmse_map(img, ref).shape == (1, 1)


def test_relmse_mean_over_pixels_and_eps():
    ref = np.full((4, 5, 3), 1.0)
    img = np.full((4, 5, 3), 1.1)
    assert M.relmse(img, ref) == pytest.approx(0.01 / 1.001, rel=1e-12)
    assert M.relmse(img, ref, eps=0.0) == pytest.approx(0.01, rel=1e-12)
    assert M.mse(img, ref) == pytest.approx(0.01, rel=1e-12)


def test_relmse_is_scale_free_but_mse_is_not():
    rng = np.random.default_rng(3)
    ref = 1.0 + rng.random((8, 8, 3))
    img = ref * (1 + 0.1 * rng.standard_normal(ref.shape))
    # relMSE(k I, k R) = relMSE(I, R) when eps << k^2 R^2 (here R >= 1, k = 100: eps changes < 1e-7)
    assert M.relmse(100 * img, 100 * ref) == pytest.approx(M.relmse(img, ref), rel=1e-3)
    assert M.mse(100 * img, 100 * ref) == pytest.approx(1e4 * M.mse(img, ref), rel=1e-12)


def test_trimmed_drops_the_top_0_01_percent():
    ref = np.ones((100, 100, 3))
    img = np.ones((100, 100, 3))
    img[3, 7] = 1001.0                          # one pixel of 10^4 is wildly wrong
    img[50:, :] += 0.1                          # half the pixels slightly off
    small = 0.01 / 1.001
    assert M.relmse(img, ref) == pytest.approx((1000.0 ** 2 / 1.001 + 5000 * small) / 1e4)
    # 0.01 % of 10^4 pixels = 1 pixel dropped: the outlier; 9999 pixels remain.
    assert M.relmse_trimmed(img, ref) == pytest.approx(5000 * small / 9999)
    assert M.relmse_trimmed(img, ref, trim=0.0) == pytest.approx(M.relmse(img, ref))
    with pytest.raises(ValueError, match="trim"):
        M.relmse_trimmed(img, ref, trim=1.0)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="shape"):
        M.relmse(np.ones((2, 2, 3)), np.ones((2, 3, 3)))
    ref = np.ones((2, 2, 3))
    ref[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="reference contains NaN"):
        M.relmse(np.ones((2, 2, 3)), ref)
    img = np.ones((2, 2, 3))
    img[1, 1, 2] = np.inf                       # a non-finite image pixel is an infinite error
    assert M.relmse(img, np.ones((2, 2, 3))) == np.inf


def test_loglog_slope_and_time_to_reach():
    t = np.array([0.1, 0.2, 0.4, 0.8, 1.6])
    s, b = M.loglog_slope(t, 3.0 / t)
    assert s == pytest.approx(-1.0, abs=1e-12) and np.exp(b) == pytest.approx(3.0)
    assert np.isnan(M.loglog_slope([1.0], [1.0])[0])
    # error = 1/t, sampled at t = 1, 2, 4: reaches 1/3 at t = 3 (exact on the log-log line)
    assert M.time_to_reach([1, 2, 4], [1, 0.5, 0.25], 1 / 3) == pytest.approx(3.0)
    assert M.time_to_reach([1, 2, 4], [1, 0.5, 0.25], 2.0) == 1.0
    assert np.isnan(M.time_to_reach([1, 2, 4], [1, 0.5, 0.25], 0.1))


def test_reference_noise_floor_predicts_measured_error():
    """A perfect image measured against a noisy reference shows relMSE ~ floor (the floor is
    estimated from two independent halves, as a Frame does)."""
    rng = np.random.default_rng(11)
    truth = 0.5 + rng.random((100, 200, 3))
    sigma = 0.05                                 # per-half standard deviation of the reference
    a = truth + sigma * rng.standard_normal(truth.shape)
    b = truth + sigma * rng.standard_normal(truth.shape)
    ref, var = 0.5 * (a + b), 0.25 * (a - b) ** 2
    measured = M.relmse(truth, ref)
    floor = M.relmse_floor(var, ref)
    # Both are means of 6e4 chi-square(1)-like terms: relative std sqrt(2/6e4) = 0.6 % each, so their
    # difference has std ~0.8 %; 4 % is 5 standard errors (the R-vs-T denominator bias is ~0.2 %).
    assert floor == pytest.approx(measured, rel=0.04)


def test_bias_variance_splits_the_mean_relmse_exactly():
    rng = np.random.default_rng(7)
    ref = rng.uniform(0.05, 2.0, (16, 12, 3))
    imgs = [ref * 1.1 + 0.05 * rng.standard_normal(ref.shape) for _ in range(5)]
    bv = M.bias_variance(imgs, ref)
    # the identity of the docstring: the mean of the renders' own relMSE, to round-off
    assert bv["relmse"] == pytest.approx(np.mean([M.relmse(im, ref) for im in imgs]), rel=1e-12)
    assert bv["renders"] == 5


def test_bias_variance_recovers_a_known_bias_and_noise():
    # X = R (1 + b) + sigma e: bias^2 and variance of the relMSE weighting are known in closed form.
    # 40 renders of 64x64x3 pixels: the estimates' relative standard errors are ~1 % (variance) and
    # ~2 % (bias^2), so 5 % tolerances are ~3 standard errors and a factor n mistake fails them
    rng = np.random.default_rng(11)
    ref = rng.uniform(0.05, 2.0, (64, 64, 3))
    b, sigma = 0.05, 0.02
    w = 1.0 / (ref * ref + M.RELMSE_EPS)
    imgs = [ref * (1 + b) + sigma * rng.standard_normal(ref.shape) for _ in range(40)]
    bv = M.bias_variance(imgs, ref)
    assert bv["variance"] == pytest.approx(np.mean(sigma ** 2 * w), rel=0.05)
    assert bv["bias2"] == pytest.approx(np.mean((b * ref) ** 2 * w), rel=0.05)


def test_bias_variance_of_an_unbiased_estimator_is_zero_on_average():
    # few renders (n = 3) each: without the -s^2/n correction the bias part would average
    # variance / 3 = 1.3e-4 here instead of 0; over 300 trials its standard error is ~5e-6
    rng = np.random.default_rng(3)
    ref = rng.uniform(0.2, 1.0, (8, 8, 3))
    parts = [M.bias_variance([ref + 0.01 * rng.standard_normal(ref.shape) for _ in range(3)], ref)
             for _ in range(300)]
    bias2 = np.array([p["bias2"] for p in parts])
    variance = np.mean([p["variance"] for p in parts])
    assert abs(bias2.mean()) < 4 * bias2.std(ddof=1) / np.sqrt(len(bias2))
    assert abs(bias2.mean()) < 0.1 * variance


def test_bias_variance_refuses_one_render_and_nonfinite_pixels():
    ref = np.ones((4, 4, 3))
    with pytest.raises(ValueError, match="at least 2"):
        M.bias_variance([ref], ref)
    bad = ref.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or Inf"):
        M.bias_variance([ref, bad], ref)


def test_bias_variance_less_the_reference_noise_and_on_a_mask():
    # a noisy reference's own variance adds the floor to bias2 once; given, it is subtracted exactly
    # (relmse_floor's sum); a mask averages over its pixels only (here: the rows with a bias)
    rng = np.random.default_rng(5)
    ref = rng.uniform(0.2, 1.0, (10, 6, 3))
    ref_var = rng.uniform(0.0, 1e-3, ref.shape)
    imgs = [ref + 0.02 * rng.standard_normal(ref.shape) for _ in range(4)]
    imgs = [im + np.where(np.arange(10)[:, None, None] < 5, 0.05, 0.0) for im in imgs]
    plain = M.bias_variance(imgs, ref)
    less = M.bias_variance(imgs, ref, reference_variance=ref_var)
    assert less["variance"] == plain["variance"]
    assert plain["bias2"] - less["bias2"] == pytest.approx(M.relmse_floor(ref_var, ref), rel=1e-9)
    top = np.zeros((10, 6), bool)
    top[:5] = True
    on = M.bias_variance(imgs, ref, mask=top)
    assert on["relmse"] == pytest.approx(np.mean([M.relmse_map(im, ref)[top].mean() for im in imgs]), rel=1e-12)
    assert on["bias2"] > 1.8 * plain["bias2"]       # the biased half only: about twice the whole's
