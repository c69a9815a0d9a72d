"""The fuzzer's gradient mode on a fixed set of random scenes (gdlearn.crosscheck.fuzz.run_gradient_seed).

Each seed's random scene goes through gpt and gpt-replay, 32 independent renders of 8 spp at
16 x 16; the mean gradient must equal the finite differences of the same runs' primal (pt's own
estimator, which tests/test_refs_fuzz.py checks against Mitsuba 3 on the same scenes) by the
statistical test of gdlearn.crosscheck.gradients (family-wise false-alarm rate 1e-3 per test).

SEEDS: a global fog lit by two directional lights (0), a bounded medium seen from outside with a
point light (4), a surface scene (1). The planted bug (Eq. 17's MIS weight replaced by 1 on both
sides of a pair, BROKEN_MIS) must fail on the surface scene: the check can fail.
"""
import pytest

from gdlearn.crosscheck import fuzz
from gdlearn.integrators.path.gpt_surface.vertex import BROKEN_MIS

SEEDS = (0, 1, 4)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["gpt", "gpt-replay"])
@pytest.mark.parametrize("seed", SEEDS)
def test_random_scene_gradients_are_unbiased(seed, integrator):
    chk, xml = fuzz.run_gradient_seed(seed, integrator)
    assert chk.ok, f"seed {seed}, {integrator}: {chk.summary()}\n{xml}"


@pytest.mark.slow
def test_planted_mis_bug_is_caught_on_a_random_scene():
    chk, _ = fuzz.run_gradient_seed(1, "gpt", broken=BROKEN_MIS)
    assert not chk.ok, f"BROKEN_MIS passed the gradient check on seed 1: {chk.summary()}"
