"""Conventions shared by every reconstruction solver: shapes, finite differences, masks, bad data.

An image is an ``H x W x C`` float64 array (a plain ``H x W`` array is accepted and returned as
``H x W``). Gradients are *forward differences* (Hua et al. 2019, Sec. 2.3, Eq. 12):

    gx[y, x] ~ I[y, x+1] - I[y, x]        gy[y, x] ~ I[y+1, x] - I[y, x]

so the last column of ``gx`` and the last row of ``gy`` describe no pixel pair: they are *masked*
(ignored whatever they hold, never counted as bad data). In matrix form ``Dx``, ``Dy`` are these
difference operators with the masked rows removed -- the discretisation of Eq. 18 -- and
``Dx^T Dx + Dy^T Dy`` is the 5-point Laplacian with Neumann (reflecting) boundaries.

Non-finite input (NaN, +-Inf) is *missing data*: it is counted per input, replaced by 0 and given
weight 0 in every solver, so it can never propagate into the result (``Reconstruction.nonfinite``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import prange

from gdlearn.reconstruct._jit import kernel

__all__ = ["Reconstruction", "Problem", "prepare", "forward_differences", "variances_from_halves",
           "pool_variance", "POOL_STATISTIC", "expand_like"]


@dataclass
class Reconstruction:
    """The result of every solver.

    image       the reconstructed image, same shape as the primal input (H x W x C or H x W);
    history     1-D array, one value per iteration (what it measures is named in ``history_kind``);
    history_kind  e.g. "fixed-point residual (RMS)", "relative residual", "L1 energy";
    nonfinite   number of non-finite input values per input name (masked entries not counted);
    iterations  iterations actually run (outer IRLS iterations for L1, 1 for the exact DCT solve);
    info        solver-specific extras (inner CG iterations, timings, parameters used, ...).
    """
    image: np.ndarray
    history: np.ndarray
    history_kind: str
    nonfinite: dict[str, int]
    iterations: int
    info: dict = field(default_factory=dict)

    @property
    def nonfinite_total(self) -> int:
        return int(sum(self.nonfinite.values()))


@kernel
def _count_nonfinite(a, skip_col, skip_row):
    """Non-finite entries of ``a``, ignoring the last column / last row when asked (masked)."""
    h, w, c = a.shape
    rows = np.zeros(h, dtype=np.int64)
    for y in prange(h):
        if skip_row and y == h - 1:
            continue
        wend = w - 1 if skip_col else w
        n = 0
        for x in range(wend):
            for k in range(c):
                if not np.isfinite(a[y, x, k]):
                    n += 1
        rows[y] = n
    return rows.sum()


@kernel
def _sanitize(a, skip_col, skip_row, out, valid):
    """out = a with non-finite and masked entries set to 0; valid = 1 where an entry is usable."""
    h, w, c = a.shape
    for y in prange(h):
        for x in range(w):
            masked = (skip_col and x == w - 1) or (skip_row and y == h - 1)
            for k in range(c):
                v = a[y, x, k]
                ok = (not masked) and np.isfinite(v)
                out[y, x, k] = v if ok else 0.0
                valid[y, x, k] = 1.0 if ok else 0.0


class Problem:
    """Validated H x W x C float64 data.

    ``complete`` is True when no (unmasked) input is non-finite; the fast paths then read
    ``primal``, ``gx``, ``gy`` directly and never touch the masked last column of ``gx`` / last
    row of ``gy`` (which may hold anything). :meth:`clean` gives copies with non-finite and masked
    entries zeroed plus 0/1 validity arrays -- what the weighted solvers use.
    """

    def __init__(self, primal, gx, gy, nonfinite, squeeze):
        self.primal, self.gx, self.gy = primal, gx, gy
        self.nonfinite = nonfinite
        self.squeeze = squeeze
        self._clean = None

    @property
    def shape(self):
        return self.primal.shape

    @property
    def complete(self) -> bool:
        return sum(self.nonfinite.values()) == 0

    def clean(self):
        """(primal, gx, gy, valid0, validx, validy), computed once."""
        if self._clean is None:
            res = []
            for a, col, row in ((self.primal, False, False), (self.gx, True, False),
                                (self.gy, False, True)):
                out = np.empty_like(a)
                valid = np.empty_like(a)
                _sanitize(a, col, row, out, valid)
                res += [out, valid]
            p, v0, x, vx, y, vy = res
            self._clean = (p, x, y, v0, vx, vy)
        return self._clean

    def finish(self, image: np.ndarray) -> np.ndarray:
        """Back to the caller's layout."""
        return image[:, :, 0] if self.squeeze else image


def _as_hwc(name: str, a, shape=None) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"{name}: expected an H x W x C (or H x W) image, got shape {a.shape}; "
                         "pass one image per call (stack channels on the last axis)")
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape} but the primal image has shape {shape}; "
                         "gx and gy must have exactly the primal's shape (forward differences, "
                         "last column of gx / last row of gy masked)")
    return np.ascontiguousarray(a)


def prepare(primal, gx, gy) -> Problem:
    """Validate shapes and count non-finite values (masked entries excluded)."""
    squeeze = np.ndim(primal) == 2
    if np.ndim(gx) != np.ndim(primal) or np.ndim(gy) != np.ndim(primal):
        raise ValueError(f"primal, gx, gy must have the same shape; got {np.shape(primal)}, "
                         f"{np.shape(gx)}, {np.shape(gy)}")
    p = _as_hwc("primal", primal)
    if min(p.shape) < 1:
        raise ValueError(f"primal: empty image of shape {p.shape}; every axis needs length >= 1")
    x = _as_hwc("gx", gx, p.shape)
    y = _as_hwc("gy", gy, p.shape)
    counts = {"primal": int(_count_nonfinite(p, False, False)),
              "gx": int(_count_nonfinite(x, True, False)),
              "gy": int(_count_nonfinite(y, False, True))}
    return Problem(p, x, y, counts, squeeze)


def expand_like(name: str, a, shape, counts: dict) -> tuple[np.ndarray, np.ndarray]:
    """A per-pixel array (H x W, H x W x 1 or H x W x C) broadcast to ``shape``.

    Returns (values with non-finite entries zeroed, validity 0/1); negative values are an error.
    """
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    try:
        a = np.broadcast_to(a, shape)
    except ValueError:
        raise ValueError(f"{name} has shape {np.shape(a)}, which does not broadcast to the image "
                         f"shape {shape}; give it as H x W, H x W x 1 or H x W x C") from None
    finite = np.isfinite(a)
    counts[name] = int(a.size - np.count_nonzero(finite))
    a = np.where(finite, a, 0.0)
    if (a < 0).any():
        raise ValueError(f"{name} has negative entries (min {a.min():.3g}); variances and weights "
                         "must be >= 0")
    return np.ascontiguousarray(a), np.ascontiguousarray(finite.astype(np.float64))


def forward_differences(image) -> tuple[np.ndarray, np.ndarray]:
    """The exact gradients of ``image`` in the convention above (masked entries set to 0)."""
    i = np.asarray(image, dtype=np.float64)
    gx = np.zeros_like(i)
    gy = np.zeros_like(i)
    gx[:, :-1] = i[:, 1:] - i[:, :-1]
    gy[:-1, :] = i[1:, :] - i[:-1, :]
    return gx, gy


#: The statistic each buffer's variance estimates are pooled with (``variances_from_halves``).
#: A pixel's variance follows the image itself -- next to a light it jumps by orders of magnitude
#: from one pixel to the next -- so a window *mean* would lend a dark pixel the variance of its
#: bright neighbour, make it distrust its own identity and pull the light's noise in; the *median*
#: ignores such a minority. The gradients' windows average (a mean over all nine pairs), which also
#: lends the pairs beside a light's rim some of the rim's variance -- measured better than the
#: median there (:mod:`gdlearn.reconstruct.cv_weights`).
POOL_STATISTIC = {"primal": "median", "gx": "mean", "gy": "mean"}


def variances_from_halves(halves: dict, pool: int = 0) -> dict[str, np.ndarray]:
    """Per-pixel variances of the full means from two independent half-buffers.

    ``halves = {"primal": (A, B), "gx": (A, B), "gy": (A, B)}`` where A and B are the means of two
    independent halves of the samples. The full mean is (A + B) / 2 and an unbiased estimate of its
    variance is (A - B)^2 / 4 (one degree of freedom per pixel: noisy, but unbiased) -- the same
    estimate as ``gdlearn.integrators.base.Frame.variance`` and the two-buffer approach the STAR
    describes for photon mapping (Hua et al. 2019, Sec. 5.2).

    ``pool = r > 0`` replaces each estimate by the larger of itself and a statistic of the
    estimates in the (2r + 1)^2 window around the pixel (:func:`~gdlearn.reconstruct.conventions.pool_variance`; the statistic per
    buffer is :data:`~gdlearn.reconstruct.conventions.POOL_STATISTIC`, ``"mean"`` for names not listed there). The window has about
    (2r + 1)^2 degrees of freedom instead of one, so a pixel whose two halves happen to agree is no
    longer trusted blindly; keeping the pixel's own estimate where it is larger stops the window
    from diluting an isolated high-variance pixel (a firefly, the edge of a light) into trust. The
    weighted control variates use r = 1 (measurements in :mod:`gdlearn.reconstruct.cv_weights`).
    """
    if int(pool) != pool or pool < 0:
        raise ValueError(f"pool = {pool!r} must be an integer >= 0 (0: per pixel, 1: 3 x 3 window)")
    out = {}
    for name, pair in halves.items():
        a, b = (np.asarray(v, dtype=np.float64) for v in pair)
        if a.shape != b.shape:
            raise ValueError(f"halves[{name!r}]: the two halves have shapes {a.shape} and "
                             f"{b.shape}; they must match")
        v = 0.25 * (a - b) ** 2
        if pool:                                    # fmax: a missing (NaN) estimate stays missing
            v = np.fmax(v, pool_variance(v, int(pool), POOL_STATISTIC.get(name, "mean")))
        out[name] = v
    return out


def pool_variance(v: np.ndarray, r: int, statistic: str = "mean") -> np.ndarray:
    """Mean (or median) of the variance estimates ``v`` (H x W or H x W x C) over the
    (2r+1) x (2r+1) window of every pixel, clipped at the image border. Non-finite entries (missing
    data) are left out of every window and stay as they are, so one NaN never spreads and a missing
    pixel stays missing. The median of an even number of values is the mean of the middle two."""
    v = np.asarray(v, dtype=np.float64)
    if statistic == "median":
        v3 = v.reshape(v.shape[0], v.shape[1], -1)
        out = np.empty_like(v3)
        _window_median(v3, int(r), out)
        return out.reshape(v.shape)
    if statistic != "mean":
        raise ValueError(f"statistic = {statistic!r}: use 'mean' or 'median'")
    ok = np.isfinite(v)
    val = np.where(ok, v, 0.0)
    pad = [(r, r), (r, r)] + [(0, 0)] * (v.ndim - 2)
    vp = np.pad(val, pad)                          # zero padding + counts = windows clipped at borders
    cp = np.pad(ok.astype(np.float64), pad)
    h, w = v.shape[0], v.shape[1]
    s = np.zeros_like(val)
    n = np.zeros_like(val)
    for dy in range(2 * r + 1):                    # a sum of non-negative terms: never below zero
        for dx in range(2 * r + 1):
            s += vp[dy:dy + h, dx:dx + w]
            n += cp[dy:dy + h, dx:dx + w]
    return np.where(ok, s / np.maximum(n, 1.0), v)


@kernel
def _window_median(v, r, out):
    """out[y, x, k] = median of the finite v in the window of (y, x), channel k (see pool_variance);
    an insertion sort of at most (2r + 1)^2 values per pixel."""
    h, w, c = v.shape
    for y in prange(h):
        buf = np.empty((2 * r + 1) ** 2)
        for x in range(w):
            for k in range(c):
                if not np.isfinite(v[y, x, k]):
                    out[y, x, k] = v[y, x, k]
                    continue
                n = 0
                for yy in range(max(y - r, 0), min(y + r + 1, h)):
                    for xx in range(max(x - r, 0), min(x + r + 1, w)):
                        e = v[yy, xx, k]
                        if np.isfinite(e):
                            i = n
                            while i > 0 and buf[i - 1] > e:
                                buf[i] = buf[i - 1]
                                i -= 1
                            buf[i] = e
                            n += 1
                out[y, x, k] = buf[n // 2] if n % 2 else 0.5 * (buf[n // 2 - 1] + buf[n // 2])
