"""Random-sequence replay: the shift mapping of the proof-of-concept gradient-domain path tracer.

Hua et al. 2019 (the STAR), Sec. 2.3 and Algorithm 1; first used for primary-sample-space
Metropolis by Kelemen et al. 2002. Book chapter: ``book/gpt-replay.md``.

The shift (Eq. 3). A base path x through pixel p is produced by the path tracer from a vector of
uniform numbers u: the film position p + (u0, u1) and then every later decision. The offset path
x' = T_pq(x) through the neighbour q = p + (dx, dy) is what the same path tracer makes from the
*same* u at the film position q + (u0, u1) -- shifted by exactly one pixel, so the pixel filter
gives h_q(T_pq(x)) = h_p(x). With counter-based random numbers (:mod:`!gdlearn.kernels.rng`) "the
same u" is simply the base pixel's key: ``rand(seed, key_of_p, sample, dim)`` evaluated while
tracing from q.

Its Jacobian (Eq. 6). u -> x and u -> x' are both the path tracer's sampling map, so
``|dx'/dx| = |dx'/du| |du/dx| = p(x) / p(x')``, and the offset term of Eq. 4 becomes (Eq. 7)::

    f(x') |dx'/dx| / p(x) = f(x') / p(x'),

which is *exactly what the path tracer returns* for u at pixel q. Replay therefore needs no
explicit Jacobian: :func:`offset_film_position` is the whole shift, and the radiance kernel's
return value is the Jacobian-weighted offset contribution.

Forward and backward shifts (Eq. 8, Eq. 16 with constant weights). The difference I_q - I_p is
estimated twice: by shifting base paths of p to q (forward) and base paths of q to p (backward,
with the sign flipped). Eq. 17's MIS weight reduces to 1/2 under replay (the Jacobian cancels the
offset density), so both get weight 0.5 (:data:`SHIFT_WEIGHTS`). Any weights with
w_fwd + w_bwd = 1 keep the estimator unbiased, since each strategy alone is unbiased; weights that
do not sum to one scale the gradient (the tests use that to prove they can fail).

Borders. A shift that would leave the image is not traced. Every gradient the library defines --
``gx[y, x]`` for x < W-1, ``gy[y, x]`` for y < H-1 -- has both its forward shift (from (x, y)) and
its backward shift (from (x+1, y) or (x, y+1)) inside the image, so it always gets both halves. The
last column of gx and the last row of gy are undefined (zero here; the reconstructions mask them).
Algorithm 1 as printed writes the backward shifts to ``G[x-1, y]`` / ``G[x, y-1]``; at x = 0 or
y = 0 that index is -1, which array code silently wraps to the last column / row. Here x and y are
handled by the same code path (:func:`gdlearn.integrators.gradients.combine_gradients`), so neither can wrap.

Russian roulette on shifts (optional). A shift may be skipped with probability 1 - q, where q is
chosen from the base contribution *before* the offset is traced (:func:`shift_survival`); a kept
shift's difference is divided by q. E[kept/q] = q (f'/p' - f/p)/q, so the gradient stays unbiased.
q has a floor ``q_min`` > 0 because a black base path can still have a bright offset (the shift's
difference is then the offset alone); q = 0 there would bias the gradient.
"""
from __future__ import annotations

import numpy as np
from gdlearn.kernels.jit import ir_inline
from gdlearn.kernels.rng import rand


#: Neighbour offsets (dx, dy) of the four shifts, in buffer order: right, left, down, up.
SHIFT_DX = np.array([1, -1, 0, 0], dtype=np.int64)
SHIFT_DY = np.array([0, 0, 1, -1], dtype=np.int64)
RIGHT, LEFT, DOWN, UP = 0, 1, 2, 3
#: (forward, backward) weights of Eq. 16: 0.5 each is Eq. 17 under replay (STAR, Sec. 3.5).
SHIFT_WEIGHTS = (0.5, 0.5)
#: RNG dimension of the shift Russian-roulette decision for shift k: far beyond any path's own
#: dimensions (2 + segment * 10 + k, at most ~41000 for volpath's 4096 segments), so the decision
#: is independent of the path it decides about.
DIM_SHIFT_RR = 1 << 40


@ir_inline
def offset_film_position(fx, fy, k):
    """T_pq on the film (Eq. 3): the base path's film position moved by exactly one pixel towards
    neighbour k (same sub-pixel jitter, so h_q(T(x)) = h_p(x)). The rest of the path is replayed by
    tracing with the base pixel's RNG key."""
    return fx + SHIFT_DX[k], fy + SHIFT_DY[k]


@ir_inline
def neighbour_inside(x, y, k, width, height):
    """Does shift k of a base path in pixel (x, y) land inside the image?"""
    nx = x + SHIFT_DX[k]
    ny = y + SHIFT_DY[k]
    return 0 <= nx < width and 0 <= ny < height


@ir_inline
def shift_survival(base, threshold, q_min):
    """Probability q of tracing a shift whose base path contributed ``base`` (rgb).

    ``threshold <= 0`` disables the roulette (q = 1). Otherwise q = clamp(mean(base) / threshold,
    q_min, 1): a base path brighter than ``threshold`` is always shifted, a dim one rarely. The
    kept difference must be divided by q (module docstring)."""
    if threshold <= 0.0:
        return 1.0
    m = (base[0] + base[1] + base[2]) / 3.0
    q = m / threshold
    if not q > q_min:           # also catches NaN
        q = q_min
    return min(q, 1.0)


@ir_inline
def shift_q(x, y, k, w, h, base, seed, key, s, rr_threshold, rr_min, counts):
    """Survival probability of shift k of the base sample (seed, key, s) in pixel (x, y) of a
    w x h image, or 0.0 if it is not traced: outside the image (``counts[1] += 1``) or skipped by
    the roulette of :func:`shift_survival`, decided with random number ``DIM_SHIFT_RR + k``
    (``counts[2] += 1``)."""
    if not neighbour_inside(x, y, k, w, h):
        counts[1] += 1
        return 0.0
    q = shift_survival(base, rr_threshold, rr_min)
    if q < 1.0 and rand(seed, key, s, DIM_SHIFT_RR + k) >= q:
        counts[2] += 1
        return 0.0
    return q


__all__ = ["SHIFT_DX", "SHIFT_DY", "RIGHT", "LEFT", "DOWN", "UP", "SHIFT_WEIGHTS", "DIM_SHIFT_RR",
           "offset_film_position", "neighbour_inside", "shift_survival", "shift_q"]
