"""gpt-replay (random-sequence replay, STAR Sec. 2.3): unbiased gradients, and tests that can fail.

The statistical test. For each of N_SEEDS independent seeds we render a small image and form, per
pixel, d = gx - (P[x+1] - P[x]) (and likewise for gy): the replay gradient minus the finite
difference of the *primal* of the same run. Both are unbiased estimators of I[x+1] - I[x] if the
shift is right, so E[d] = 0; the mean of d over the seeds and its standard error (spread over the
seeds / sqrt(N)) give a t statistic per 2x2 pixel block (channels averaged). The seeds are
independent, so the t statistics follow Student's t with N-1 degrees of freedom (path-tracing
samples are skewed; with 8 spp x 4 pixels x 3 channels averaged per block and per seed the
seed means are close to normal).

Two tests on the same differences, both at a family-wise false-alarm rate FAMILY_ALPHA = 1e-3 (a
correct shift fails about once in a thousand seed sets; the seeds are fixed, so nothing flickers):

* local: |t| per block below k = the Bonferroni bound for the number of blocks of gx and gy (a
  bias confined to a few pixels -- a border bug, a wrapped index -- shows here);
* global: the projection of d on an independent pilot's gradients (:func:`projected_t`), which
  adds a bias proportional to the gradients up over the whole image.

Power: the same test with both shift weights 0.6 instead of 0.5 -- every gradient scaled by 1.2 --
must fail (asserted: a test that cannot fail proves nothing). Note what is *not* a broken shift:
Eq. 16 with weights (0.7, 0.3), or offsets that do not replay the jitter, are still unbiased (each
offset is then still a valid path-traced sample of its pixel); only the variance suffers.
"""
import numpy as np
import pytest

from gdlearn.crosscheck.gradients import block_t, differences, projected_t
from gdlearn.integrators import make, render
from gdlearn.scene.load import load

ROOT = __file__.rsplit("/tests/", 1)[0]
RES = 16
N_SEEDS = 32
SPP = 8
PILOT_SPP = 128


def _scene(name):
    return load(f"{ROOT}/scenes/{name}.xml", res=RES)


def _frames(scene, weights=None, **opts):
    out = []
    for seed in range(N_SEEDS):
        integ = make("gpt-replay", scene, seed=1000 + seed, spp_per_pass=SPP, **opts)
        if weights is not None:          # deliberately break Eq. 16 (bypasses the constructor's check)
            integ.shift_weights = weights
        out.append(render(integ, spp=SPP))
    return out


def _pilot(scene):
    # seed 7 is not among the test seeds (1000...), so the pilot is independent of the frames
    return render(make("pt", scene, seed=7, spp_per_pass=PILOT_SPP // 4), spp=PILOT_SPP)


@pytest.fixture(scope="module")
def cornell():
    return _scene("cornell-box")


@pytest.fixture(scope="module")
def fog():
    return _scene("fog-box")


def _assert_unbiased(scene, **opts):
    dx, dy = differences(_frames(scene, **opts))
    tx, ty, k = block_t(dx, dy)
    assert tx.max() < k and ty.max() < k, (
        f"replay gradients differ from the finite differences of the primal in some block: max |t| "
        f"gx {tx.max():.2f}, gy {ty.max():.2f} > k = {k:.2f}")
    px, py, pxy, kp = projected_t(dx, dy, _pilot(scene))
    assert max(px, py, pxy) < kp, (
        f"gradients biased along the image's own gradients: |t| gx {px:.2f}, gy {py:.2f}, both {pxy:.2f} "
        f"> {kp:.2f}")


def test_cornell_box_gradients_are_unbiased(cornell):
    _assert_unbiased(cornell)


def test_fog_box_gradients_are_unbiased(fog):
    _assert_unbiased(fog)


def test_unbiased_with_russian_roulette_on_shifts(cornell):
    # threshold 1 (a bright base is always shifted), floor 0.2: about half the shifts are skipped
    _assert_unbiased(cornell, shift_rr=1.0, shift_rr_min=0.2)


def test_a_wrong_shift_weight_fails_the_same_test(cornell, fog):
    """Weights 0.6 + 0.6 (sum 1.2) scale every gradient by 1.2: the projections must see it, in gx
    and in gy separately on the Cornell box, in both together in the (dimmer, smoother) fog box."""
    pilot = _pilot(cornell)
    px, py, _, kp = projected_t(*differences(_frames(cornell, weights=(0.6, 0.6))), pilot)
    assert px > kp and py > kp, f"the test cannot see a 20% bias: |t| gx {px:.2f}, gy {py:.2f} <= {kp:.2f}"
    _, _, pxy, kp = projected_t(*differences(_frames(fog, weights=(0.6, 0.6))), _pilot(fog))
    assert pxy > kp, f"the test cannot see a 20% bias in fog: |t| {pxy:.2f} <= {kp:.2f}"


def test_primal_is_the_path_tracers_image_bit_for_bit(cornell):
    # the base paths are pt's, sample for sample: the same seed must give the same primal
    g = render(make("gpt-replay", cornell, seed=3, spp_per_pass=2), spp=4)
    p = render(make("pt", cornell, seed=3, spp_per_pass=2), spp=4)
    assert p.primal.mean() > 0 and np.array_equal(g.primal, p.primal)


def test_shift_counts_and_undefined_borders(cornell):
    spp, w, h = 3, RES, RES
    f = render(make("gpt-replay", cornell, seed=2, spp_per_pass=spp), spp=spp)
    # every border pixel's outward shift is not traced: W (top) + W (bottom) + H (left) + H (right)
    assert f.stats["shifts_outside"] == spp * (2 * w + 2 * h)
    assert f.stats["shifts_traced"] + f.stats["nonfinite_samples"] == spp * (4 * w * h - 2 * w - 2 * h)
    assert f.stats["shifts_rr_skipped"] == 0
    assert np.all(f.gx[:, -1] == 0) and np.all(f.gy[-1, :] == 0)
    assert np.abs(f.gx[:, :-1]).max() > 0 and np.abs(f.gy[:-1, :]).max() > 0


def test_russian_roulette_skips_shifts(cornell):
    f = render(make("gpt-replay", cornell, seed=2, spp_per_pass=2, shift_rr=1.0, shift_rr_min=0.2), spp=2)
    total = 2 * (4 * RES * RES - 4 * RES)
    # dim base paths (most of the Cornell box is below radiance 1) are shifted with q < 1
    assert 0.2 * total < f.stats["shifts_rr_skipped"] < 0.9 * total
    assert f.stats["shifts_traced"] + f.stats["shifts_rr_skipped"] + f.stats["nonfinite_samples"] == total


def test_combine_gradients_never_wraps_around_the_border():
    """Algorithm 1's backward writes G[x-1] at x = 0 would wrap to the last column in array code;
    here the backward shift of pixel 0 (which leaves the image) must not reach any gradient."""
    from gdlearn.integrators.gradients import combine_gradients
    from gdlearn.shifts.replay import DOWN, LEFT, RIGHT, UP
    h, w = 4, 5
    diffs = np.zeros((4, h, w))
    diffs[RIGHT] = 1.0               # forward: I[x+1] - I[x] = 1
    diffs[LEFT] = -1.0               # backward: offset(x-1) - base(x) = -1, i.e. the same gradient 1
    diffs[LEFT][:, 0] = 99.0         # garbage where the shift left the image
    diffs[DOWN] = 2.0
    diffs[UP] = -2.0
    diffs[UP][0, :] = 99.0
    gx, gy = combine_gradients(diffs)
    np.testing.assert_array_equal(gx[:, :-1], 1.0)
    np.testing.assert_array_equal(gx[:, -1], 0.0)
    np.testing.assert_array_equal(gy[:-1, :], 2.0)
    np.testing.assert_array_equal(gy[-1, :], 0.0)


def test_bad_options_are_refused(cornell):
    with pytest.raises(ValueError, match="must be 1"):
        make("gpt-replay", cornell, shift_weights=(0.6, 0.6))
    with pytest.raises(ValueError, match="shift_rr"):
        make("gpt-replay", cornell, shift_rr=-1.0)
    with pytest.raises(ValueError, match="bias"):
        make("gpt-replay", cornell, shift_rr=1.0, shift_rr_min=0.0)


def test_decorrelation_map(cornell):
    integ = make("gpt-replay", cornell, seed=3, spp_per_pass=4)
    integ.warmup()
    maps = integ.decorrelation(spp=4)
    assert maps["relative"].shape == maps["other_surface"].shape == (RES, RES)
    assert np.all((maps["other_surface"] >= 0) & (maps["other_surface"] <= 1))
    # the same samples as the first pass of a render: the primal matches pt's
    p = render(make("pt", cornell, seed=3, spp_per_pass=4), spp=4).primal
    assert np.array_equal(maps["primal"], p)
    # at 16x16 the box's edges (walls, light, boxes) cross many pixels: some shifts change surface,
    # and those pixels decorrelate more (mean relative difference) than the rest
    edge = maps["other_surface"] > 0
    rel = np.where(np.isfinite(maps["relative"]), maps["relative"], 10.0)
    assert 0 < edge.mean() < 1 and np.median(rel[edge]) > np.median(rel[~edge])
