"""``lights.pick_prim``: an area emitter's primitive chosen by its cdf, the first entry > u.

Up to 8 entries it counts the entries <= u (no branch); beyond, it searches by bisection. Both
must give numpy's ``searchsorted(cdf, u, side="right")`` (clipped to the last entry), also where u
equals an entry exactly and where entries repeat (zero-area triangles), and on a slice of the
scene's shared cdf array (``first`` > 0). Counting with < instead of <= fails the exact-equality
cases; a slice read from the wrong offset fails them all.
"""
import numpy as np
import pytest

from gdlearn.kernels.lights import pick_prim


def _expected(cdf, u):
    return min(int(np.searchsorted(cdf, u, side="right")), len(cdf) - 1)


@pytest.mark.parametrize("count", [1, 2, 3, 7, 8, 9, 16, 33])
def test_pick_prim_is_the_first_entry_above_u(count):
    rng = np.random.default_rng(count)
    for trial in range(40):
        w = rng.random(count)
        w[rng.random(count) < 0.2] = 0.0                  # zero-area primitives: repeated entries
        if w.sum() == 0.0:
            w[-1] = 1.0
        cdf = np.cumsum(w) / w.sum()
        cdf[-1] = 1.0
        pad = rng.integers(0, 5)                           # the emitter's slice of the shared array
        shared = np.concatenate([rng.random(pad), cdf, rng.random(3)])
        us = np.concatenate([rng.random(20), cdf[:-1], [0.0, np.nextafter(1.0, 0.0)]])
        for u in us:
            assert pick_prim(shared, pad, count, u) - pad == _expected(cdf, u), (count, trial, u)
