"""Counter-based random numbers: a hash of (seed, key, sample index, dimension).

Like pbrt-v4's ``Hash(p, seed)`` + ``Advance(sampleIndex * 65536 + dimension)``, every random
number is a pure function of its coordinates, never of a stream's history. Three things follow:

* images do not depend on the number of threads or the order in which pixels are rendered;
* a render is reproducible from its seed;
* random-sequence replay -- the book's first shift mapping (Hua et al. 2019, Sec. 2.3) -- is simply
  "the same key, another pixel": an offset path evaluates ``rand(seed, key_of_base_pixel, s, d)``.

Key spaces. Camera paths use ``key = y * width + x`` (below 2^40 for any image). Light paths use
``key = LIGHT_KEY0 + j`` for light path j, with the pass index as ``sample``
(:mod:`gdlearn.integrators.photon_base`): the two spaces never meet, so a photon map is independent
of the image size, of the thread count and of the pixels' random numbers.

The hash is SplitMix64's finaliser (Steele et al. 2014, "Fast splittable pseudorandom number
generators"; it passes BigCrush as a counter-based generator), applied in a chain of four -- one per
coordinate -- so it falls into two stages, and a path pays the expensive one once:

1. ``path_state(seed, key, sample)``: the first three finalisers hash the path's coordinates into a
   64-bit state ``h``. Each stage is a bijection of its coordinate for fixed others
   (multiplication by the odd golden-ratio constant, xor with a constant, the finaliser are all
   invertible mod 2^64): two pixels -- or two samples of a pixel -- never share a state.
2. ``rand_at(h, dim)``: the fourth finaliser of ``h ^ (dim * GOLDEN + C)``, again a bijection of
   ``dim``: the numbers along a path are distinct finaliser outputs of distinct inputs.

``rand(seed, key, sample, dim) = rand_at(path_state(seed, key, sample), dim)`` is the contract, bit
for bit (seed-calibrated statistical tests and stored results rely on it). The path kernels compute the state once per path and call
:func:`rand_at`: one finaliser per number instead of four.
"""
import numpy as np
from gdlearn.kernels.jit import inlined


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_C_SAMPLE = np.uint64(0x632BE59BD9B4E019)
_C_DIM = np.uint64(0x85157AF5)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_ONE = np.uint64(1)
_INV53 = 1.0 / 9007199254740992.0   # 2^-53

#: first key of the light paths' key space (camera paths: the pixel index, always below it)
LIGHT_KEY0 = 1 << 40


@inlined
def mix64(z):
    """SplitMix64 finaliser: a bijective avalanche on 64-bit integers."""
    z = np.uint64(z)
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@inlined
def path_state(seed, key, sample):
    """The 64-bit state of the path (seed, key, sample): the first three stages of :func:`hash4`."""
    h = mix64(np.uint64(seed) * _GOLDEN + _ONE)
    h = mix64(h ^ (np.uint64(key) * _GOLDEN))
    return mix64(h ^ (np.uint64(sample) * _GOLDEN + _C_SAMPLE))


@inlined
def hash_at(h, dim):
    """The 64-bit hash of dimension ``dim`` of the path with state ``h`` (the last stage)."""
    return mix64(h ^ (np.uint64(dim) * _GOLDEN + _C_DIM))


@inlined
def hash4(seed, key, sample, dim):
    """A 64-bit hash of four non-negative integers."""
    return hash_at(path_state(seed, key, sample), dim)


@inlined
def rand_at(h, dim):
    """A uniform float64 in [0, 1) for dimension ``dim`` of the path with state ``h``; 53 bits."""
    return float(hash_at(h, dim) >> _S11) * _INV53


@inlined
def rand(seed, key, sample, dim):
    """A uniform float64 in [0, 1) for the coordinates (seed, key, sample, dim); 53 random bits.
    Equal, bit for bit, to ``rand_at(path_state(seed, key, sample), dim)``."""
    return rand_at(path_state(seed, key, sample), dim)
