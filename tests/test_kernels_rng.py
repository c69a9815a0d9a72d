"""The counter-based RNG (gdlearn.kernels.rng): its contract and its statistics.

* the contract: ``rand(seed, key, sample, dim)`` is a pure function of the four coordinates and
  equals ``rand_at(path_state(seed, key, sample), dim)`` bit for bit (the path tracer uses the
  second form, random-sequence replay and the gradient kernels the first);
* the construction: a chain of four SplitMix64 finalisers (checked against SplitMix64's published
  first outputs for seed 0) whose first three hash the path -- checked against a pure-Python
  reimplementation of the chain (independent of numba), which pins the numbers themselves: the
  split into path state and dimension must not change a single bit;
* statistics (chi^2 against the uniform law, at a false-alarm rate of 1e-4 per test): numbers
  along one path, across pixels for one dimension, across samples, and pairs of neighbouring
  dimensions / neighbouring pixels (the places a weak counter-based hash shows correlations).
"""
import numpy as np
import pytest
from numba import njit
from scipy import stats

from gdlearn.kernels.rng import hash_at, mix64, path_state, rand, rand_at

ALPHA = 1e-4
M64 = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15


def _mix64_py(z):
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9 & M64
    z = (z ^ (z >> 27)) * 0x94D049BB133111EB & M64
    return z ^ (z >> 31)


def _path_state_py(seed, key, sample):
    h = _mix64_py((seed * GOLDEN + 1) & M64)
    h = _mix64_py(h ^ (key * GOLDEN & M64))
    return _mix64_py(h ^ ((sample * GOLDEN + 0x632BE59BD9B4E019) & M64))


def _hash4_py(seed, key, sample, dim):
    return _mix64_py(_path_state_py(seed, key, sample) ^ ((dim * GOLDEN + 0x85157AF5) & M64))


@njit(cache=True)
def _grid(seed, keys, samples, dims):
    out = np.empty((keys, samples, dims))
    for k in range(keys):
        for s in range(samples):
            for d in range(dims):
                out[k, s, d] = rand(seed, k, s, d)
    return out


@njit(cache=True)
def _two_forms(seed, key, sample, dims):
    h = path_state(seed, key, sample)
    n = 0
    for d in range(dims):
        n += rand(seed, key, sample, d) == rand_at(h, d)
    return n


@njit(cache=True)
def _hashes(h, n):
    out = np.empty(n, dtype=np.uint64)
    for d in range(n):
        out[d] = hash_at(h, d)
    return out


@njit(cache=True)
def _states(seed, keys, sample):
    out = np.empty(keys, dtype=np.uint64)
    for k in range(keys):
        out[k] = path_state(seed, k, sample)
    return out


def test_both_forms_agree_bit_for_bit():
    rng = np.random.default_rng(0)
    for seed, key, sample in rng.integers(0, 2**31, size=(50, 3)):
        assert _two_forms(int(seed), int(key), int(sample), 200) == 200


@njit(cache=True)
def _mix(z):
    return mix64(z)


def test_the_hash_is_the_chain_of_four_finalisers():
    # the finaliser: SplitMix64 (Steele et al. 2014) seeded with 0 outputs mix64(k * GOLDEN), k = 1, 2, ...
    assert [int(_mix(np.uint64((k * GOLDEN) & M64))) for k in range(1, 5)] == [
        0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F, 0xF88BB8A8724C81EC]
    for seed, key, sample in [(0, 0, 0), (7, 12345, 3), (2**31 - 1, 65535, 1023)]:
        h = _path_state_py(seed, key, sample)
        assert int(path_state(seed, key, sample)) == h
        want = [_hash4_py(seed, key, sample, d) for d in range(16)]
        assert [int(x) for x in _hashes(np.uint64(h), 16)] == want
        assert [rand(seed, key, sample, d) for d in range(16)] == [(w >> 11) * 2.0**-53 for w in want]


def test_states_of_distinct_pixels_differ():
    s = _states(3, 1 << 18, 5)
    assert len(np.unique(s)) == len(s)


def _chi2_uniform(u, bins=64):
    counts = np.bincount(np.minimum((u * bins).astype(int), bins - 1), minlength=bins)
    return stats.chisquare(counts).pvalue


def _chi2_pairs(a, b, bins=16):
    ia = np.minimum((a * bins).astype(int), bins - 1)
    ib = np.minimum((b * bins).astype(int), bins - 1)
    counts = np.bincount(ia * bins + ib, minlength=bins * bins)
    return stats.chisquare(counts).pvalue


def test_range_and_uniformity():
    g = _grid(11, 512, 16, 48)                       # 393216 numbers
    assert g.min() >= 0.0 and g.max() < 1.0
    assert _chi2_uniform(g.reshape(-1)) > ALPHA
    assert _chi2_uniform(g[:, :, 0].reshape(-1)) > ALPHA            # one dimension, every path
    assert _chi2_uniform(g[:, 0, :].reshape(-1)) > ALPHA            # sample 0 of every pixel
    assert _chi2_uniform(g[0, :, :].reshape(-1), bins=16) > ALPHA   # one pixel, every sample


@pytest.mark.parametrize("what", ["neighbour dims", "neighbour pixels", "neighbour samples"])
def test_neighbours_are_independent(what):
    g = _grid(5, 1024, 8, 32)
    if what == "neighbour dims":
        a, b = g[:, :, :-1], g[:, :, 1:]
    elif what == "neighbour pixels":
        a, b = g[:-1], g[1:]
    else:
        a, b = g[:, :-1], g[:, 1:]
    assert _chi2_pairs(a.reshape(-1), b.reshape(-1)) > ALPHA
    r = np.corrcoef(a.reshape(-1), b.reshape(-1))[0, 1]
    assert abs(r) < 5.0 / np.sqrt(a.size)


def test_seeds_give_independent_images():
    a, b = _grid(1, 256, 4, 16), _grid(2, 256, 4, 16)
    assert _chi2_pairs(a.reshape(-1), b.reshape(-1)) > ALPHA
