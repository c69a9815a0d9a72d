"""The solver adapter hands frames to gdlearn.reconstruct by name (and survives pickling)."""
import pickle

import numpy as np
import pytest

from experiments_fake import truth
from gdlearn.experiments import solvers
from gdlearn.experiments.metrics import relmse
from gdlearn.integrators.base import Frame

pytest.importorskip("gdlearn.reconstruct.poisson")


def _exact_frame(noise=0.0, seed=0):
    t = truth(6, 8)
    gx, gy = np.zeros_like(t), np.zeros_like(t)
    gx[:, :-1] = t[:, 1:] - t[:, :-1]
    gy[:-1] = t[1:] - t[:-1]
    rng = np.random.default_rng(seed)
    imgs = {"primal": t + noise * rng.standard_normal(t.shape), "gx": gx, "gy": gy}
    # halves that differ a little, so weighted solvers see finite, non-zero variances
    halves = {n: (v + 0.01, v - 0.01) for n, v in imgs.items()}
    return t, Frame(2, 2, imgs, halves, {}, {}, 0.0)


@pytest.mark.parametrize("name", ["cv", "l2", "l1"])
def test_exact_data_is_recovered(name):
    t, frame = _exact_frame()
    # exact primal and exact gradients are a fixed point of every solver (to round-off: 1e-20)
    assert relmse(solvers.final_image(frame, name), t) < 1e-20


@pytest.mark.parametrize("name", ["cv", "cv-weighted", "l2"])
def test_exact_gradients_remove_primal_noise(name):
    t, frame = _exact_frame(noise=0.1, seed=1)
    # with exact gradients the reconstruction can only lower the primal's error
    assert relmse(solvers.final_image(frame, name), t) < 0.5 * relmse(frame.primal, t)


def test_weighted_passes_the_frame_halves():
    # cv-weighted hands the frame's half-buffers to control_variates, which estimates (and pools)
    # the variances itself: the same image as calling it directly with halves=
    from gdlearn.reconstruct import control_variates
    _, frame = _exact_frame(noise=0.1, seed=2)
    direct = control_variates(frame.primal, frame.gx, frame.gy,
                              halves={n: frame.halves[n] for n in ("primal", "gx", "gy")})
    np.testing.assert_array_equal(solvers.final_image(frame, "cv-weighted"), direct.image)


def test_names_errors_and_pickling():
    assert solvers.resolve(None) is None
    with pytest.raises(ValueError, match="unknown solver"):
        solvers.resolve("l3")
    fn = pickle.loads(pickle.dumps(solvers.resolve("l2")))
    t, frame = _exact_frame()
    assert relmse(fn(frame), t) < 1e-20
    prim = Frame(1, 1, {"primal": t}, {"primal": (t, t)}, {}, {}, 0.0)
    with pytest.raises(ValueError, match="needs gradient images"):
        fn(prim)
