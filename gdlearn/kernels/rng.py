"""Counter-based random numbers: a hash of (seed, key, sample index, dimension).

Like pbrt-v4's ``Hash(p, seed)`` + ``Advance(sampleIndex * 65536 + dimension)``, every random
number is a pure function of its coordinates, never of a stream's history. Three things follow:

* images do not depend on the number of threads or the order in which pixels are rendered;
* a render is reproducible from its seed;
* random-sequence replay -- the book's first shift mapping (Hua et al. 2019, Sec. 2.3) -- is simply
  "the same key, another pixel": an offset path evaluates ``rand(seed, key_of_base_pixel, s, d)``.

The hash is SplitMix64's finaliser (Steele et al. 2014), applied in a chain; it passes BigCrush
as a counter-based generator. ``key`` is usually the pixel index ``y * width + x``.
"""
import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0   # 2^-53


@njit(cache=True, inline="always")
def mix64(z):
    """SplitMix64 finaliser: a bijective avalanche on 64-bit integers."""
    z = np.uint64(z)
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, inline="always")
def hash4(seed, key, sample, dim):
    """A 64-bit hash of four non-negative integers."""
    h = mix64(np.uint64(seed) * _GOLDEN + np.uint64(1))
    h = mix64(h ^ (np.uint64(key) * _GOLDEN))
    h = mix64(h ^ (np.uint64(sample) * _GOLDEN + np.uint64(0x632BE59BD9B4E019)))
    return mix64(h ^ (np.uint64(dim) * _GOLDEN + np.uint64(0x85157AF5)))


@njit(cache=True, inline="always")
def rand(seed, key, sample, dim):
    """A uniform float64 in [0, 1) for the coordinates (seed, key, sample, dim); 53 random bits."""
    return float(hash4(seed, key, sample, dim) >> _S11) * _INV53
