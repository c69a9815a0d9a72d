"""gdlearn.experiments.gradients: the gradient-error metric (hand-computed values), the equal-sample
study on the toy estimators (exact truth known), shift statistics and summaries."""
import numpy as np
import pytest

from gdlearn.experiments import Method
from gdlearn.experiments.gradients import (finite_differences, gradient_errors, gradient_relmse,
                                           gradient_relmse_maps, shift_summary, summarize,
                                           summed_stats)
from gdlearn.experiments.metrics import RELMSE_EPS
from gdlearn.teaching.toy import ToyGradient, ToyPrimal, ToyScene


def test_gradient_relmse_hand_computed():
    ref = np.array([[1.0, 3.0], [1.0, 1.0]])
    # the undefined last column of gx / last row of gy hold garbage that must be ignored
    gx = np.array([[2.5, np.nan], [0.5, np.inf]])
    gy = np.array([[0.0, -2.0], [np.nan, 7.0]])
    # gx: (2.5 - 2)^2 / (2^2 + eps) and (0.5 - 0)^2 / (1^2 + eps); gy: both exact
    expected = (0.25 / (4 + RELMSE_EPS) + 0.25 / (1 + RELMSE_EPS)) / 4
    assert gradient_relmse(gx, gy, ref) == pytest.approx(expected, rel=1e-12)
    ex, ey = gradient_relmse_maps(gx, gy, ref)
    assert ex.shape == (2, 1) and ey.shape == (1, 2)


def test_exact_differences_have_zero_error_and_nonfinite_counts_as_inf():
    rng = np.random.default_rng(3)
    ref = rng.random((5, 7, 3))
    gx, gy = finite_differences(ref)
    assert gx[0, 0, 1] == ref[0, 1, 1] - ref[0, 0, 1] and gy[2, 3, 0] == ref[3, 3, 0] - ref[2, 3, 0]
    assert gradient_relmse(gx, gy, ref) == 0.0
    gx[1, 1, 2] = np.nan                      # a defined gradient that is NaN must not be hidden
    assert gradient_relmse(gx, gy, ref) == np.inf


def test_shape_mismatch_names_the_fix():
    with pytest.raises(ValueError, match="same resolution"):
        gradient_relmse(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), np.zeros((5, 4, 3)))


def test_toy_study_gradients_beat_finite_differences_and_scale_as_one_over_n():
    scene = ToyScene(width=32, height=24)
    truth = scene.truth()                     # exact pixel integrals, independent of the estimators
    methods = [Method("toy-pt", ToyPrimal), Method("toy-gpt", ToyGradient)]
    rec = {spp: gradient_errors(methods, [scene], spp=spp, seeds=12, references={"toy": truth})
           for spp in (4, 16)}
    s4, s16 = summarize(rec[4]), summarize(rec[16])
    assert [r["shifted"] for r in rec[4][::12]] == [False, True]   # pt: finite differences of its primal
    assert s4[("toy-pt", "toy")]["n"] == 12 and np.isfinite(s4[("toy-pt", "toy")]["stderr"])
    # Shared (offset, weight) samples cancel on the smooth ramp but not at the edge and the bright
    # rectangle: the toy's gradients beat independent finite differences by ~4.5x (measured at
    # 16 spp); a factor 2 leaves room for the heavy-tailed seeds.
    assert s16[("toy-gpt", "toy")]["mean"] * 2 < s16[("toy-pt", "toy")]["mean"]
    # Unbiased estimators against an exact truth: the expected error is the variance, exactly 1/spp,
    # so 4 -> 16 spp divides it by 4. Tolerance: k = 3 standard errors of the ratio (relative
    # standard errors of both means, combined in quadrature, from the 12 seeds themselves).
    for m in ("toy-pt", "toy-gpt"):
        a, b = s4[(m, "toy")], s16[(m, "toy")]
        ratio = a["mean"] / b["mean"]
        rel_se = np.hypot(a["stderr"] / a["mean"], b["stderr"] / b["mean"])
        assert abs(ratio - 4.0) < 3 * 4.0 * rel_se, (m, ratio, rel_se)


def test_shift_summary_hand_numbers():
    stats = {"paths": 100, "shift_replay_run": 0, "shift_replay_ok": 0, "shift_reconnection_run": 50,
             "shift_reconnection_ok": 40, "shift_reconnection_failed": 10, "shift_fail_run": 5,
             "shift_fail_ok": 0}
    s = shift_summary(stats)
    assert set(s) == {"replay", "reconnection", "fail"}         # only the counters the frame has
    assert s["reconnection"] == {"per_path": 0.5, "success": 0.8}
    assert np.isnan(s["replay"]["success"]) and s["fail"]["success"] == 0.0


def test_summed_stats_adds_the_counters_of_records():
    recs = [{"method": "a", "seed": 0, "n_paths": 10, "n_shift_fail_run": 1, "relmse": 0.5},
            {"method": "a", "seed": 1, "n_paths": 30, "n_shift_fail_run": 2, "n_bad": 4}]
    assert summed_stats(recs) == {"paths": 40, "shift_fail_run": 3, "bad": 4}
    assert shift_summary(summed_stats(recs))["fail"]["per_path"] == pytest.approx(3 / 40)


def test_summarize_mean_and_standard_error():
    recs = [{"method": "a", "scene": "s", "grad_relmse": v} for v in (1.0, 2.0, 3.0)]
    s = summarize(recs)[("a", "s")]
    assert s["mean"] == 2.0 and s["n"] == 3
    assert s["stderr"] == pytest.approx(1.0 / np.sqrt(3))       # sample std 1, over sqrt(3)
