"""Hard cases for every reconstruction solver: non-finite input, all-zero images, 1 x N / N x 1
images, alpha -> 0, a dynamic range of 1e-6 ... 1e6, and malformed input."""
import numpy as np
import pytest

from gdlearn.reconstruct import control_variates, poisson_l1, poisson_l2
from test_reconstruct_poisson import smooth_image, sparse_solve, true_gradients

SOLVERS = {
    "cv": lambda p, gx, gy, **kw: control_variates(p, gx, gy, **kw),
    "cv-weighted": lambda p, gx, gy, **kw: control_variates(
        p, gx, gy, variances={"primal": np.full(p.shape, 0.5), "gx": np.full(p.shape, 0.1),
                              "gy": np.full(p.shape, 0.2)}, **kw),
    "l2": lambda p, gx, gy, **kw: poisson_l2(p, gx, gy, **kw),
    "l2-weighted": lambda p, gx, gy, **kw: poisson_l2(p, gx, gy, weights=(2.0, 0.5, 1.5), tol=1e-13,
                                                      **kw),
    "l1": lambda p, gx, gy, **kw: poisson_l1(p, gx, gy, **kw),
}


def poke(a, rng, n, values):
    """Write ``values`` into n random defined entries (never the masked column / row)."""
    idx = []
    for _ in range(n):
        idx.append((rng.integers(0, a.shape[0] - 1), rng.integers(0, a.shape[1] - 1),
                    rng.integers(0, a.shape[2])))
    idx = sorted(set(idx))
    for i, j in enumerate(idx):
        a[j] = values[i % len(values)]
    return len(idx)


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_nonfinite_input_is_counted_and_contained(name):
    """Exact data with NaN / +-Inf sprinkled in: the missing values are counted exactly, and since
    the remaining data are still consistent every solver recovers the image to round-off."""
    rng = np.random.default_rng(0)
    img = smooth_image(19, 23)
    gx, gy = true_gradients(img)
    p = img.copy()
    bad = [np.nan, np.inf, -np.inf]
    n0, nx, ny = poke(p, rng, 6, bad), poke(gx, rng, 6, bad), poke(gy, rng, 6, bad)
    gx[:, -1] = np.nan                   # masked: neither counted nor used
    gy[-1] = np.inf
    res = SOLVERS[name](p, gx, gy)
    counts = dict(res.nonfinite)
    assert {k: counts.pop(k) for k in ("primal", "gx", "gy")} == {"primal": n0, "gx": nx, "gy": ny}
    assert not any(counts.values())      # variances / weights were all finite
    assert np.all(np.isfinite(res.image))
    # CV sums exact identities (1e-12); PCG stops at relative residual 1e-10 (1e-13 weighted);
    # IRLS starts from the L2 solve (PCG to 1e-10) and exact data leave nothing to reweight:
    # 1e-7 allows the start's tolerance times the problem's conditioning (values ~5)
    assert np.abs(res.image - img).max() < 1e-7


def test_nonfinite_variances_and_weights_are_counted_and_ignored():
    rng = np.random.default_rng(7)
    img = smooth_image(10, 12)
    gx, gy = true_gradients(img)
    var = {k: rng.uniform(0.1, 1.0, img.shape) for k in ("primal", "gx", "gy")}
    var["gx"][2, 3, 1] = np.nan
    var["gx"][4, -1, 0] = np.nan          # masked column: not data, not counted
    var["primal"][5, 5, 2] = np.inf
    res = control_variates(img, gx, gy, variances=var)
    assert res.nonfinite["var_gx"] == 1 and res.nonfinite["var_primal"] == 1
    assert np.abs(res.image - img).max() < 1e-12
    w = np.ones(img.shape)
    w[1, 1, 0] = np.nan
    res = poisson_l2(img, gx, gy, weights=(w, 1.0, 1.0), tol=1e-13)
    assert res.nonfinite["weights.primal"] == 1
    assert np.abs(res.image - img).max() < 1e-9


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_missing_pixel_with_no_data_stays_finite(name):
    """A pixel whose primal and all four gradients are NaN has no identity at all."""
    rng = np.random.default_rng(1)
    p = 1.0 + 0.1 * rng.standard_normal((9, 9, 3))
    gx, gy = 0.01 * rng.standard_normal((2, 9, 9, 3))
    p[4, 4] = np.nan
    gx[4, 3] = gx[4, 4] = gy[3, 4] = gy[4, 4] = np.nan
    res = SOLVERS[name](p, gx, gy)
    assert np.all(np.isfinite(res.image)) and res.nonfinite_total == 3 + 4 * 3
    # it falls back to a value within the range of its channel's data
    assert np.all(np.abs(res.image[4, 4] - 1.0) < 1.0)


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_all_zero_image(name):
    z = np.zeros((7, 10, 3))
    res = SOLVERS[name](z, z, z)
    assert np.array_equal(res.image, z)
    assert np.all(np.isfinite(res.history))


@pytest.mark.parametrize("name", sorted(SOLVERS))
@pytest.mark.parametrize("shape", [(1, 17), (17, 1), (1, 1)])
def test_degenerate_shapes_recover_exact_data(name, shape):
    rng = np.random.default_rng(2)
    img = 2.0 + np.cumsum(rng.standard_normal(shape), axis=int(np.argmax(shape))) * 0.1
    gx, gy = true_gradients(img[..., None])
    res = SOLVERS[name](img, gx[..., 0], gy[..., 0])    # 2-D input: 2-D output
    assert res.image.shape == shape
    assert np.abs(res.image - img).max() < 1e-9


@pytest.mark.parametrize("shape", [(1, 17), (17, 1)])
def test_degenerate_shapes_l2_matches_sparse(shape):
    rng = np.random.default_rng(3)
    p, gx, gy = rng.standard_normal((3,) + shape + (2,))
    ref = sparse_solve(p, gx, gy, 0.2)
    assert np.abs(poisson_l2(p, gx, gy).image - ref).max() < 1e-10
    assert np.abs(poisson_l2(p, gx, gy, weights=(1.0, 1.0, 1.0), tol=1e-14).image - ref).max() < 1e-10


@pytest.mark.parametrize("solver", ["l2", "l2-weighted", "l1"])
@pytest.mark.parametrize("alpha", [0.0, 1e-12])
def test_alpha_to_zero_integrates_gradients(solver, alpha):
    """Exact gradients, noisy primal, alpha -> 0: the gradients determine the image up to a
    constant, fixed to the primal's mean (weighted: its weighted mean; the weights are constant
    here so it is the same)."""
    rng = np.random.default_rng(4)
    img = smooth_image(15, 12)
    gx, gy = true_gradients(img)
    p = img + 0.5 * rng.standard_normal(img.shape)
    res = SOLVERS[solver](p, gx, gy, alpha=alpha)
    target = img + (p - img).mean(axis=(0, 1))
    # alpha = 1e-12 differs from the limit by O(alpha^2); solver tolerances as in the tests above
    assert np.abs(res.image - target).max() < 1e-7


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_dynamic_range_1e_minus6_to_1e6(name):
    """An HDR image spanning twelve decades. Exact data is recovered to round-off relative to the
    largest value (1e-16 x 1e6 per operation; 1e-9 x max leaves room for ~1e4 operations)."""
    y, x = np.mgrid[0:16, 0:20]
    logv = -6.0 + 12.0 * (x + y) / (16 + 20 - 2)
    img = np.stack([10.0 ** logv, 10.0 ** (-logv), np.full(logv.shape, 1e-6)], axis=-1)
    gx, gy = true_gradients(img)
    res = SOLVERS[name](img, gx, gy)
    assert np.all(np.isfinite(res.image))
    assert np.abs(res.image - img).max() <= 1e-9 * np.abs(img).max()


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_l2_and_cv_are_scale_invariant(scale):
    rng = np.random.default_rng(5)
    p, gx, gy = rng.standard_normal((3, 12, 14, 3))
    for f in (poisson_l2, control_variates):
        a = f(p, gx, gy).image
        b = f(scale * p, scale * gx, scale * gy).image
        assert np.allclose(b, scale * a, rtol=1e-10, atol=1e-10 * scale)


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_l1_tiny_and_huge_values_stay_sensible(scale):
    """eps is absolute (as in the reference), so L1 is not scale invariant -- but it stays finite
    and never ends above the L2 start's L1 energy."""
    rng = np.random.default_rng(6)
    p, gx, gy = scale * rng.standard_normal((3, 12, 14, 3))
    res = poisson_l1(p, gx, gy)
    assert np.all(np.isfinite(res.image)) and np.all(np.isfinite(res.history))
    assert res.history[-1] <= res.history[0] * (1 + 1e-9)


def test_shape_mismatches_raise_clear_errors():
    p = np.zeros((5, 6, 3))
    with pytest.raises(ValueError, match=r"gx has shape \(5, 7, 3\)"):
        poisson_l2(p, np.zeros((5, 7, 3)), p)
    with pytest.raises(ValueError, match="same shape"):
        control_variates(p, np.zeros((5, 6)), p)
    with pytest.raises(ValueError, match="H x W x C"):
        poisson_l1(np.zeros((2, 2, 2, 2)), np.zeros((2, 2, 2, 2)), np.zeros((2, 2, 2, 2)))
    with pytest.raises(ValueError, match="empty"):
        poisson_l2(np.zeros((0, 4, 3)), np.zeros((0, 4, 3)), np.zeros((0, 4, 3)))
    with pytest.raises(ValueError, match="does not broadcast"):
        control_variates(p, p, p, variances={"primal": np.ones((4, 6)), "gx": 0 * p, "gy": 0 * p})
    with pytest.raises(ValueError, match="does not broadcast"):
        poisson_l2(p, p, p, weights=(np.ones((5, 5)), 1.0, 1.0))


def test_bad_parameters_raise_clear_errors():
    p = np.zeros((5, 6, 3))
    with pytest.raises(ValueError, match="alpha"):
        poisson_l2(p, p, p, alpha=-0.1)
    with pytest.raises(ValueError, match="alpha"):
        poisson_l1(p, p, p, alpha=np.nan)
    with pytest.raises(ValueError, match="negative"):
        poisson_l2(p, p, p, weights=(1.0, -np.ones((5, 6)), 1.0))
    with pytest.raises(ValueError, match="missing"):
        control_variates(p, p, p, variances={"primal": p})
    with pytest.raises(ValueError, match="iterations"):
        control_variates(p, p, p, iterations=-1)
    with pytest.raises(ValueError, match="irls_iterations"):
        poisson_l1(p, p, p, irls_iterations=0)
