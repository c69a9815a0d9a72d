"""The camera distance copy (Gruson et al. 2018, §4.1): the offset lands at the base's distance,
on the right sub-segment of its ray, with Jacobian dt'/dt = 1 (checked by finite differences of
the map as the offset flight applies it)."""
import numpy as np

from gdlearn.shifts import distance as D


def _copy(tau, segments):
    """The offset's scattering distance along a ray cut into ``segments`` (lengths) by null
    interfaces, as offset_flight walks it; None when the ray ends first."""
    travelled = 0.0
    for t in segments:
        lands, tl = D.lands_on_segment(tau, travelled, t)
        if lands:
            return travelled + tl
        travelled += t
    return None


def test_the_copy_keeps_the_distance_across_null_interfaces():
    rng = np.random.default_rng(3)
    for _ in range(200):
        segs = rng.uniform(0.05, 1.0, size=rng.integers(1, 6))
        tau = rng.uniform(0.0, segs.sum() * 1.5)
        got = _copy(tau, segs)
        if tau < segs.sum():
            assert got is not None and abs(got - tau) < 1e-12
        else:                                  # the offset ray is shorter: the shift fails
            assert got is None


def test_the_jacobian_is_one_by_finite_differences():
    segs = [0.3, 0.25, 0.7]
    h = 1e-6
    for tau in (0.1, 0.31, 0.9, 1.2):
        fd = (_copy(tau + h, segs) - _copy(tau - h, segs)) / (2 * h)
        assert abs(fd - D.JACOBIAN) < 1e-8


def test_a_segment_starting_past_tau_by_rounding_is_clamped():
    assert D.lands_on_segment(1.0, 1.0 + 1e-17, 0.5) == (True, 0.0)
    assert D.lands_on_segment(2.0, 0.0, 1.0) == (False, 0.0)
