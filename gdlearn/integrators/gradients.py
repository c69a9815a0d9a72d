"""The gradient buffer contract every gradient-domain estimator writes, and how it becomes images.

A gradient estimator's kernel writes, per *base* pixel p and per shift k (right, left, down, up;
:data:`gdlearn.shifts.replay.SHIFT_DX` / ``SHIFT_DY``), three kinds of per-pass means:

* ``L``    -- the base contribution (the primal estimator's sample);
* ``D_k``  -- the gradient sample of shift k: the sum over techniques of w (C' - C), -C for a
  failed shift (STAR, Hua et al. 2019, Eq. 16);
* ``S_k``  -- the weighted offset contribution sum w C' (0 for a failed or outside shift).

Keeping them per base pixel means a row-parallel kernel never has two rows adding into one element;
:func:`combine_gradients` assembles the forward-difference images gx, gy afterwards and
:func:`mis_primal` the MIS-weighted primal (Kettunen et al. 2015). gpt-replay writes L and D_k
with constant weights; gpt, and the photon estimators' gradient versions (Hua et al. 2017;
Gruson et al. 2018), write all three with Eq. 17 / Eq. 11 / Eq. 19 weights inside the buffers.
"""
from __future__ import annotations

import numpy as np

from gdlearn.shifts.replay import DOWN, LEFT, RIGHT, SHIFT_DX, SHIFT_DY, SHIFT_WEIGHTS, UP


def combine_gradients(diffs: np.ndarray, weights=SHIFT_WEIGHTS) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8 / Eq. 16 with constant weights: forward-difference gradients from per-base-pixel shift
    differences.

    ``diffs[k, y, x]`` is the mean over base paths of pixel (x, y) of (offset - base) for shift k
    (order :data:`!RIGHT`, :data:`!LEFT`, :data:`!DOWN`, :data:`!UP`); entries of shifts that left the
    image are ignored. Returns ``gx, gy`` (H x W [x C]) with

        gx[y, x] = w_f * diffs[RIGHT, y, x] - w_b * diffs[LEFT, y, x+1]   (x < W-1)
        gy[y, x] = w_f * diffs[DOWN, y, x]  - w_b * diffs[UP, y+1, x]     (y < H-1)

    (the backward shift from q to p estimates I_p - I_q, hence the minus) and zeros in the
    undefined last column of gx / last row of gy. The buffers are separate per base pixel so that a
    row-parallel kernel never has two rows adding into one element.
    """
    w_f, w_b = weights
    diffs = np.asarray(diffs, dtype=np.float64)
    gx = np.zeros_like(diffs[RIGHT])
    gy = np.zeros_like(diffs[DOWN])
    gx[:, :-1] = w_f * diffs[RIGHT, :, :-1] - w_b * diffs[LEFT, :, 1:]
    gy[:-1, :] = w_f * diffs[DOWN, :-1, :] - w_b * diffs[UP, 1:, :]
    return gx, gy


def mis_primal(out: np.ndarray) -> np.ndarray:
    """Kettunen et al. 2015's primal image (Sec. 4 of their paper; STAR Sec. 3.5, Eq. 16-17): every
    pair of neighbours (p, q = p + dir_k) has two techniques for I_p, "sample in p" and "sample in q,
    shift back to p", combined by the balance weights of Eq. 17 that the kernel already applied. With
    the kernel's buffers ``out`` (9, H, W, 3) (:func:`!gpt_rows`: L, D_k, S_k) pair k estimates

        I_p ~ (S_k - D_k)[p] + S_opp(k)[p + dir_k]      (= w C of p's paths + w' C' of q's offsets)

    where S_k - D_k is w C for a shift that succeeded and C (weight 1) for one that failed. A pair whose
    neighbour lies outside the image has only the first technique with weight 1: L[p]. Each pair is
    unbiased for I_p; the result is their mean (1/4 each)."""
    out = np.asarray(out, dtype=np.float64)
    base = out[0]
    h, w = base.shape[:2]
    acc = np.zeros_like(base)
    for k in range(4):
        dx, dy = int(SHIFT_DX[k]), int(SHIFT_DY[k])
        term = base.copy()
        y0, y1 = max(0, -dy), h - max(0, dy)     # pixels p whose neighbour p + dir_k is inside
        x0, x1 = max(0, -dx), w - max(0, dx)
        own = out[5 + k, y0:y1, x0:x1] - out[1 + k, y0:y1, x0:x1]
        back = out[5 + (k ^ 1), y0 + dy:y1 + dy, x0 + dx:x1 + dx]   # k ^ 1: right <-> left, down <-> up
        term[y0:y1, x0:x1] = own + back
        acc += term
    return 0.25 * acc


def pass_halves(buffers: np.ndarray, names) -> dict:
    """The images of a photon pass's two halves: for each half of ``buffers`` (2, 9, H, W, 3: L, D_k,
    S_k with the MIS weights inside, PHOTONS.md Sec. 0.2) the MIS primal, the base L, gx and gy,
    under ``names`` (four names, None for an image not kept), as lists of the two halves' images."""
    out = {n: [] for n in names if n}
    for b in buffers:
        gx, gy = combine_gradients(b[1:5], (1.0, 1.0))
        for name, img in zip(names, (mis_primal(b), b[0], gx, gy)):
            if name:
                out[name].append(img)
    return out


__all__ = ["combine_gradients", "mis_primal", "pass_halves"]
