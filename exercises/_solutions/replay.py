"""Solution of the exercise "replay" (exercises/replay/README.md).

The loop is written out (gdlearn's own loop is a numba kernel over scenes,
:mod:`gdlearn.integrators.path.gpt_replay`); it keeps one buffer of (offset - base) per shift direction
and base pixel and combines them with gdlearn's :func:`gdlearn.integrators.gradients.combine_gradients`
(Eq. 8 / Eq. 16 with weights 0.5), so a backward shift never wraps around the border. The
reconstruction is gdlearn's uniform control variates (Eq. 14), which average only the identities
that exist at the borders.
"""
import numpy as np

from gdlearn.reconstruct import control_variates
from gdlearn.integrators.gradients import combine_gradients
from gdlearn.shifts.replay import SHIFT_DX, SHIFT_DY


def accumulate(radiance, width: int, height: int, spp: int, seed: int, dims: int = 4):
    rng = np.random.default_rng(seed)
    primal = np.zeros((height, width))
    diffs = np.zeros((4, height, width))          # mean (offset - base) per shift k and base pixel
    for y in range(height):
        for x in range(width):
            for _ in range(spp):
                u = rng.random(dims)
                base = radiance(u, x + u[0], y + u[1])
                primal[y, x] += base
                for k in range(4):
                    nx, ny = x + SHIFT_DX[k], y + SHIFT_DY[k]
                    if 0 <= nx < width and 0 <= ny < height:       # a shift never leaves the image
                        diffs[k, y, x] += radiance(u, nx + u[0], ny + u[1]) - base
    gx, gy = combine_gradients(diffs / spp)
    return primal / spp, gx, gy


def reconstruct(P, Gx, Gy, iterations: int = 50):
    return control_variates(P, Gx, Gy, iterations=iterations).image


__all__ = ["accumulate", "reconstruct"]
