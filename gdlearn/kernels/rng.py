"""Counter-based random numbers: a hash of (seed, key, sample index, dimension).

Like pbrt-v4's ``Hash(p, seed)`` + ``Advance(sampleIndex * 65536 + dimension)``, every random
number is a pure function of its coordinates, never of a stream's history. Three things follow:

* images do not depend on the number of threads or the order in which pixels are rendered;
* a render is reproducible from its seed;
* random-sequence replay -- the book's first shift mapping (Hua et al. 2019, Sec. 2.3) -- is simply
  "the same key, another pixel": an offset path evaluates ``rand(seed, key_of_base_pixel, s, d)``.

``key`` is usually the pixel index ``y * width + x``.

Construction (two stages, so a path pays the expensive part once):

1. ``path_state(seed, key, sample)``: three chained SplitMix64 finalisers (Steele et al. 2014,
   "Fast splittable pseudorandom number generators") hash the path's coordinates into a 64-bit
   state ``h``. For fixed other coordinates each stage is a bijection (multiplication by the odd
   golden-ratio constant, xor with a constant, and the finaliser are all invertible mod 2^64), so
   two pixels -- or two samples of a pixel -- never share a state; unrelated coordinates collide
   with probability 2^-64, as for any 64-bit hash.
2. ``rand_at(h, dim) = mix64(h + (dim + 1) * GOLDEN)``: exactly SplitMix64's output function with
   ``h`` as its seed -- dimension ``dim`` of a path is the (dim + 1)-th number of the SplitMix64
   stream seeded by ``h``. SplitMix64 (a Weyl sequence through the finaliser) passes BigCrush
   (Steele et al. 2014, Sec. 5), so the numbers *along* a path are as good as SplitMix64's.
   *Across* paths, two streams can only repeat each other shifted by k dimensions if their states
   differ by exactly k * GOLDEN (mod 2^64): for D dimensions that is a chance of ~2 D / 2^64 per
   pair of paths (with D = 100: one pair in ~10^17), the same order as a collision of the single
   64-bit hash of all four coordinates used before.

``rand(seed, key, sample, dim) = rand_at(path_state(seed, key, sample), dim)`` is the contract: a
pure function of its four coordinates. Kernels that draw many numbers for one path compute the
state once and call :func:`rand_at` (one finaliser per number instead of four; measured on the
Cornell box: see benchmarks/README.md); both forms give identical bits.
"""
import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_C_SAMPLE = np.uint64(0x632BE59BD9B4E019)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_ONE = np.uint64(1)
_INV53 = 1.0 / 9007199254740992.0   # 2^-53


@njit(cache=True, forceinline=True)
def mix64(z):
    """SplitMix64 finaliser: a bijective avalanche on 64-bit integers."""
    z = np.uint64(z)
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, forceinline=True)
def path_state(seed, key, sample):
    """The 64-bit state of the path (seed, key, sample): the seed of its SplitMix64 stream."""
    h = mix64(np.uint64(seed) * _GOLDEN + _ONE)
    h = mix64(h ^ (np.uint64(key) * _GOLDEN))
    return mix64(h ^ (np.uint64(sample) * _GOLDEN + _C_SAMPLE))


@njit(cache=True, forceinline=True)
def hash_at(h, dim):
    """The 64-bit hash of dimension ``dim`` of the path with state ``h`` (SplitMix64 output dim+1)."""
    return mix64(h + (np.uint64(dim) + _ONE) * _GOLDEN)


@njit(cache=True, forceinline=True)
def hash4(seed, key, sample, dim):
    """A 64-bit hash of four non-negative integers."""
    return hash_at(path_state(seed, key, sample), dim)


@njit(cache=True, forceinline=True)
def rand_at(h, dim):
    """A uniform float64 in [0, 1) for dimension ``dim`` of the path with state ``h``; 53 bits."""
    return float(hash_at(h, dim) >> _S11) * _INV53


@njit(cache=True, forceinline=True)
def rand(seed, key, sample, dim):
    """A uniform float64 in [0, 1) for the coordinates (seed, key, sample, dim); 53 random bits.
    Equal, bit for bit, to ``rand_at(path_state(seed, key, sample), dim)``."""
    return rand_at(path_state(seed, key, sample), dim)
