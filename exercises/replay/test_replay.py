"""Tests of the exercise "replay". Each docstring is the line `gdlearn check` prints.

A recording radiance function logs every call (u, fx, fy, value), so the tests can see what the
loop did -- which random numbers it replayed where -- and compute from the log alone what Algorithm 1
must return. All randomness is seeded, so a result never changes between runs.
"""
import math

import numpy as np
import pytest

from gdlearn.teaching.exercises import load_target
from gdlearn.reconstruct import control_variates

ex = load_target("replay")

W, H, SPP = 5, 4, 3


class Recorder:
    """radiance(u, fx, fy): a smooth image times a path-like random factor; logs every call."""

    def __init__(self):
        self.calls = []

    def __call__(self, u, fx, fy):
        v = math.sin(0.9 * fx) + 0.5 * math.cos(1.3 * fy) + 2.0 + float(u[2]) * (1.0 + 0.2 * fx) - float(u[3])
        self.calls.append((tuple(float(a) for a in u), float(fx), float(fy), v))
        return v


def _run(rec=None, width=W, height=H, spp=SPP, seed=3):
    rec = rec or Recorder()
    out = ex.accumulate(rec, width, height, spp, seed)
    assert isinstance(out, tuple) and len(out) == 3, "accumulate must return (P, Gx, Gy)"
    p, gx, gy = (np.asarray(a, dtype=float) for a in out)
    for name, a in (("P", p), ("Gx", gx), ("Gy", gy)):
        assert a.shape == (height, width), f"{name} has shape {a.shape}, expected (height, width) = {(height, width)}"
    return rec, p, gx, gy


def _paths(rec):
    """Group the log by u: {u: [(pixel, frac, value), ...]} with the pixel of each call."""
    groups = {}
    for u, fx, fy, v in rec.calls:
        px, py = math.floor(fx + 1e-9), math.floor(fy + 1e-9)
        groups.setdefault(u, []).append(((px, py), (fx - px, fy - py), v))
    return groups


def _base(calls):
    """The base call: the one every other call of the same u is a 4-neighbour of."""
    for c in calls:
        if all(abs(o[0][0] - c[0][0]) + abs(o[0][1] - c[0][1]) == 1 for o in calls if o is not c):
            return c
    raise AssertionError("the calls made with one u are not a pixel and its 4-neighbours: "
                         f"pixels {[c[0] for c in calls]}")


def test_every_pixel_gets_spp_base_paths_and_u_is_replayed():
    """each pixel gets spp base paths; each u is replayed at the neighbours with the same jitter"""
    rec, *_ = _run()
    groups = _paths(rec)
    assert len(groups) == W * H * SPP, (f"{len(groups)} different u for {W}x{H} pixels x {SPP} spp: draw a new "
                                        "u for every base sample and reuse it (not a fresh one) for its shifts")
    count = np.zeros((H, W), dtype=int)
    for calls in groups.values():
        base = _base(calls)
        count[base[0][1], base[0][0]] += 1
        for c in calls:
            assert np.allclose(c[1], base[1], atol=1e-9), (
                f"the offset path at pixel {c[0]} has jitter {c[1]}, the base path {base[1]}: the film position "
                "must move by exactly one pixel (replay u[0], u[1] too)")
    assert (count == SPP).all(), f"base paths per pixel:\n{count}\nexpected {SPP} everywhere"


def test_shifts_stay_inside_the_image_and_reach_all_neighbours():
    """shifts go to every neighbour inside the image and never outside it"""
    rec, *_ = _run()
    for calls in _paths(rec).values():
        base = _base(calls)
        (x, y) = base[0]
        want = {(x + dx, y + dy) for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))
                if 0 <= x + dx < W and 0 <= y + dy < H}
        got = {c[0] for c in calls if c is not base}
        assert got == want, f"base pixel {(x, y)}: shifts to {sorted(got)}, expected {sorted(want)}"


def test_gradients_follow_algorithm_1():
    """P and the 0.5-weighted forward + backward gradients equal what the recorded paths give"""
    rec, p, gx, gy = _run()
    ep, egx, egy = np.zeros((H, W)), np.zeros((H, W)), np.zeros((H, W))
    for calls in _paths(rec).values():
        base = _base(calls)
        (x, y), vb = base[0], base[2]
        ep[y, x] += vb / SPP
        for (qx, qy), _, vo in (c for c in calls if c is not base):
            if qx == x + 1:
                egx[y, x] += 0.5 * (vo - vb) / SPP        # forward: I[x+1] - I[x]
            elif qx == x - 1:
                egx[y, qx] += 0.5 * (vb - vo) / SPP       # backward: also I[x] - I[x-1]
            elif qy == y + 1:
                egy[y, x] += 0.5 * (vo - vb) / SPP
            else:
                egy[qy, x] += 0.5 * (vb - vo) / SPP
    np.testing.assert_allclose(p, ep, atol=1e-12, err_msg="P is not the mean of the base paths")
    assert np.all(gx[:, -1] == 0) and np.all(gy[-1, :] == 0), (
        "the last column of Gx / last row of Gy must stay 0 (undefined); did a backward shift at x = 0 "
        "or y = 0 write to index -1?")
    ok_x = np.allclose(gx, egx, atol=1e-12)
    ok_y = np.allclose(gy, egy, atol=1e-12)
    hint = ""
    if not (ok_x and ok_y):
        ratio = np.sum(gx * egx) / max(np.sum(egx * egx), 1e-300)
        hint = f" (your Gx is ~{ratio:.2f} x the expected one: weights 0.5 for each of the two shift directions?)"
    assert ok_x, "Gx differs from Algorithm 1's 0.5 * forward + 0.5 * backward estimate" + hint
    assert ok_y, "Gy differs from Algorithm 1's 0.5 * forward + 0.5 * backward estimate" + hint


def test_a_linear_ramp_has_exact_gradients():
    """an image I = 2 fx + 3 fy: every replayed gradient is exactly 2 (x) and 3 (y), noise-free"""
    _, p, gx, gy = _run(lambda u, fx, fy: 2.0 * fx + 3.0 * fy, width=6, height=5, spp=2)
    # 1e-12: the difference of two ramp values at the same jitter is exact up to round-off
    assert np.allclose(gx[:, :-1], 2.0, atol=1e-12), f"Gx of the ramp:\n{np.round(gx, 3)}\nexpected 2"
    assert np.allclose(gy[:-1, :], 3.0, atol=1e-12), f"Gy of the ramp:\n{np.round(gy, 3)}\nexpected 3"


def test_reconstruct_one_iteration_by_hand():
    """one iteration of Eq. 14 on a 1x3 image matches the hand-computed values"""
    P = np.array([[1.0, 4.0, 2.0]])
    Gx = np.array([[2.0, -1.0, 0.0]])
    Gy = np.zeros((1, 3))
    # pixel 0: (I0 + I1 - Gx0) / 2 = (1 + 2) / 2; pixel 1: (I1 + I0 + Gx0 + I2 - Gx1) / 3 = (4 + 3 + 3) / 3;
    # pixel 2: (I2 + I1 + Gx1) / 2 = (2 + 3) / 2
    want = np.array([[1.5, 10.0 / 3.0, 2.5]])
    got = np.asarray(ex.reconstruct(P, Gx, Gy, iterations=1), dtype=float)
    assert got.shape == P.shape, f"reconstruct returned shape {got.shape}, expected {P.shape}"
    assert np.allclose(got, want, atol=1e-12), (f"one iteration gave {got.ravel()}, expected {want.ravel()}: "
                                                 "average only the identities of neighbours inside the image")


def test_reconstruct_recovers_exact_data():
    """exact gradients and primal of an image are a fixed point: the image comes back unchanged"""
    t = np.random.default_rng(1).random((6, 7))
    gx, gy = np.zeros_like(t), np.zeros_like(t)
    gx[:, :-1], gy[:-1, :] = np.diff(t, axis=1), np.diff(t, axis=0)
    got = np.asarray(ex.reconstruct(t, gx, gy, iterations=20), dtype=float)
    assert np.allclose(got, t, atol=1e-12), "exact data must stay unchanged (check the signs of the gradients)"


def test_reconstruct_matches_gdlearn():
    """30 iterations on noisy data agree with gdlearn.reconstruct.control_variates"""
    rng = np.random.default_rng(2)
    P, Gx, Gy = rng.random((5, 6)), rng.normal(size=(5, 6)), rng.normal(size=(5, 6))
    Gx[:, -1], Gy[-1, :] = 0.0, 0.0
    want = control_variates(P, Gx, Gy, iterations=30).image
    got = np.asarray(ex.reconstruct(P, Gx, Gy, iterations=30), dtype=float)
    assert np.allclose(got, want, atol=1e-10), f"max difference {np.abs(got - want).max():.3g} after 30 iterations"
