"""The randomized differential test against Mitsuba 3 (gdlearn.crosscheck.fuzz) on a fixed set of seeds.

Each seed is one random scene of the documented subset, rendered at 16 x 16 by gdlearn's pt (8 batches
of 64 spp) and by Mitsuba 3 scalar_rgb (8 seeds of 128 spp), compared by the block test
(alpha = 1e-3 family-wise per scene, image mean within 5 %). The seeds are fixed, so the scenes and
the random numbers are too: a pass is reproducible and a failure is a real difference (or a 1e-3
false alarm, which a re-run with other seeds would not repeat).

PASSING: seeds that cover the surface path tracer, bounded media with the camera outside (4, 11: a
point and a spot light) and inside (5, 7), a global medium lit by two directional lights (0: the
fuzzer's first find, shadow rays to emitters at infinity 2 r long from points outside the bounding
sphere; now 2 max(r, |p - c|) as Mitsuba 3), max_depth 1 (23: a constant background seen through a
bounded medium's transmittance) to unbounded. The injected-bias test shows the harness can fail:
the medium's sigma_s scaled by 0.95 in gdlearn's copy of the scene only. A new mismatch the fuzzer
finds and that is not fixed yet goes into a strict-xfail list here, so it turns red once fixed.
"""
import importlib.util

import pytest

from gdlearn.crosscheck import fuzz

pytestmark = [pytest.mark.mitsuba, pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None,
                                                      reason="Mitsuba 3 is not installed (the [ref] extra)")]

PASSING = (0, 1, 4, 5, 7, 10, 11, 23)


@pytest.mark.slow
@pytest.mark.parametrize("seed", PASSING)
def test_random_scene_matches_mitsuba(seed):
    v = fuzz.run_seed(seed)
    assert v.ok, f"seed {seed}: {v.summary}\n{v.xml}"


@pytest.mark.slow
def test_injected_sigma_s_bias_is_caught():
    """sigma_s * 0.95 (the albedo scaled at constant sigma_t) in gdlearn's scene only, on a bounded
    medium seed (5: the camera inside a null sphere of medium; measured 26 of 48 blocks beyond the
    bound, worst z = -13): the comparison must fail."""
    v = fuzz.run_seed(INJECT_SEED, inject=fuzz.INJECTIONS["sigma_s*0.95"])
    assert not v.ok, f"a 5 % sigma_s bias passed on seed {INJECT_SEED}: {v.summary}"


INJECT_SEED = 5
