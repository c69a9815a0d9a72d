"""Iterative control-variate reconstruction (Rousselle et al. 2016; Hua et al. 2019, Sec. 2.3, 5.2).

Each pixel is re-estimated from five identities (Eq. 9-13): itself and each 4-neighbour q plus the
gradient between them, ``<I_p> = <I_q> + <I_p - I_q>``. With the gradients held fixed this is a
fixed point ``I = F(I)`` iterated from the primal image (Eq. 11):

    uniform  (Eq. 14, Algorithm 1 ``reconstruct``):  I_c' = (I_c + I_r - Gx_c + I_l + Gx_l
                                                               + I_b - Gy_c + I_t + Gy_t) / 5
    weighted (Eq. 20-22):  I_p' = sum_{q in N_p + {p}} w_pq (I_q + <I_p - I_q>),
                           w_pq = s_pq^-2 / sum_r s_pr^-2,
                           s_pq^2 = var(I_p^(n)) + var(<I_q - I_p>)

For the weighted form the variance of the *iterate* ``var(I_p^(n))`` is unknown; as the STAR says
(after Eq. 22) it is approximated by the primal variance divided by a constant, here
``iterate_variance_divisor`` (default 5: the variance of a mean of five equally noisy identities).
The self term has ``s_pp^2 = var(I_p^(n))`` (its "gradient" is exactly 0), and using var(I_p) rather
than var(I_q) in every term is Rousselle et al.'s choice against energy loss (STAR, after Eq. 22).
Consequence worth knowing: with equal, non-zero primal and gradient variances the weights are *not*
uniform -- the self term is trusted more; they are uniform when the gradient variances vanish.

Variances from two half-buffers (``halves=``) are estimated and pooled over each pixel's 3 x 3
window (``variance_pool=1``) as :mod:`gdlearn.reconstruct.cv_weights` explains and measures;
explicit ``variances=`` are used as given.

Boundaries and missing data: a pixel averages only the identities that exist -- neighbours inside
the image whose gradient is finite, itself if its primal is finite (the reference implementation
averages over the neighbours present, too). A pixel with no identity at all keeps its start value
(its channel's mean over valid primal pixels).

Uniform CV is damped Jacobi (weight 4/5 in the interior) on the pure (alpha = 0) Poisson equation
``L I = Dx^T Gx + Dy^T Gy`` started from the primal: the early stop after 30-50 iterations (Sec. 2.3)
plays the role that alpha plays in the screened Poisson solvers.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from gdlearn.reconstruct._jit import kernel

from gdlearn.reconstruct.conventions import Reconstruction, expand_like, prepare, variances_from_halves
from gdlearn.reconstruct.cv_weights import weighted_step, weights

#: window radius over which variances estimated from half-buffers are pooled (cv_weights)
VARIANCE_POOL = 1

__all__ = ["control_variates", "cv_history", "CVHistory"]


@kernel
def _uniform_offsets(gx, gy, out):
    """c_p = sum_q w_pq <I_p - I_q> for uniform weights over the neighbours inside the image."""
    h, w, c = gx.shape
    for y in prange(h):
        for x in range(w):
            n = 1.0 + (x > 0) + (x + 1 < w) + (y > 0) + (y + 1 < h)
            for k in range(c):
                v = 0.0                    # the masked last column / row is never read
                if x + 1 < w:
                    v -= gx[y, x, k]
                if y + 1 < h:
                    v -= gy[y, x, k]
                if x > 0:
                    v += gx[y, x - 1, k]
                if y > 0:
                    v += gy[y - 1, x, k]
                out[y, x, k] = v / n


#: LLVM may reassociate the sums and fuse multiply-adds in the uniform step, so that its interior
#: loop (and the squared-change reduction) vectorises; results move by round-off only (~1e-16).
_VECTORISE = {"reassoc", "nsz", "contract"}


@njit(cache=True, fastmath=_VECTORISE)
def _uniform_row(a, au, ad, o, r, c, up, dn, inv):
    """Eq. 14 on the interior columns of one row, flattened to x * c + k (neighbours at j -/+ c):
    no per-pixel branches, so the loop vectorises; returns the sum of squared changes."""
    s = 0.0
    n = a.shape[0]
    if up and dn:
        for j in range(c, n - c):
            v = (a[j] + a[j - c] + a[j + c] + au[j] + ad[j]) * inv + o[j]
            d = v - a[j]
            s += d * d
            r[j] = v
    else:                                  # first or last row (or a single row)
        for j in range(c, n - c):
            v = a[j] + a[j - c] + a[j + c]
            if up:
                v += au[j]
            if dn:
                v += ad[j]
            v = v * inv + o[j]
            d = v - a[j]
            s += d * d
            r[j] = v
    return s


@kernel(fastmath=_VECTORISE)
def _uniform_step(img, off, out, c):
    """One Eq. 14 iteration (complete data) on H x (W * C) views; returns the sum of squared changes.
    Memory-bound: one read of img and off and one write of out per iteration."""
    h, n = img.shape
    w = n // c
    rows = np.zeros(h)
    for y in prange(h):
        up, dn = y > 0, y + 1 < h
        a, o, r = img[y], off[y], out[y]
        au = img[y - 1] if up else a
        ad = img[y + 1] if dn else a
        base = 1.0 + up + dn
        s = _uniform_row(a, au, ad, o, r, c, up, dn, 1.0 / (base + 2.0))
        for x in range(0, w, max(w - 1, 1)):      # the border columns 0 and W - 1
            inv = 1.0 / (base + (x > 0) + (x + 1 < w))
            for k in range(c):
                j = x * c + k
                v = a[j]
                if x > 0:
                    v += a[j - c]
                if x + 1 < w:
                    v += a[j + c]
                if up:
                    v += au[j]
                if dn:
                    v += ad[j]
                v = v * inv + o[j]
                d = v - a[j]
                s += d * d
                r[j] = v
        rows[y] = s
    return rows.sum()


def _unmask(v, shape, axis):
    """The gradient variance with its masked last column (x) / row (y) set to 0: not data."""
    v = np.asarray(v, dtype=np.float64)
    v = v[:, :, None] if v.ndim == 2 else v
    try:
        v = np.array(np.broadcast_to(v, shape))
    except ValueError:
        raise ValueError(f"variance of g{axis} has shape {v.shape}, which does not broadcast to "
                         f"the image shape {shape}; give it as H x W, H x W x 1 or H x W x C"
                         ) from None
    if axis == "x":
        v[:, -1] = 0.0
    else:
        v[-1] = 0.0
    return v


def _setup(primal, gx, gy, variances, halves, divisor, pool):
    """Validate, then return (problem, counts, step function taking (img, out))."""
    prob = prepare(primal, gx, gy)
    counts = dict(prob.nonfinite)
    if variances is not None and halves is not None:
        raise ValueError("control_variates: give either variances or halves, not both")
    if halves is not None:
        variances = variances_from_halves(halves, pool=pool)
    if not (np.isfinite(divisor) and divisor > 0):
        raise ValueError(f"iterate_variance_divisor = {divisor!r} must be a finite number > 0")
    if variances is None and prob.complete:
        off = np.empty_like(prob.primal)
        _uniform_offsets(prob.gx, prob.gy, off)
        h, c = off.shape[0], off.shape[2]
        flat = off.reshape(h, -1)

        def step(img, out):       # img and out are C-contiguous H x W x C: the reshapes are views
            return _uniform_step(img.reshape(h, -1), flat, out.reshape(h, -1), c)
        return prob, counts, step, "uniform"
    shape = prob.shape
    if variances is None:             # uniform over the present identities: all variances equal
        v0 = vx = vy = np.zeros(shape)
        ok0v = okxv = okyv = np.ones(shape)
        kind = "uniform"
    else:
        missing = {"primal", "gx", "gy"} - set(variances)
        if missing:
            raise ValueError(f"variances: missing {sorted(missing)}; give per-pixel variances of "
                             "'primal', 'gx' and 'gy' (or halves=... to estimate them)")
        v0, ok0v = expand_like("var_primal", variances["primal"], shape, counts)
        vx, okxv = expand_like("var_gx", _unmask(variances["gx"], shape, "x"), shape, counts)
        vy, okyv = expand_like("var_gy", _unmask(variances["gy"], shape, "y"), shape, counts)
        kind = "weighted"
    _, cgx, cgy, valid0, validx, validy = prob.clean()
    w4 = [np.empty(shape) for _ in range(5)]
    weights(v0, vx, vy, valid0 * ok0v, validx * okxv, validy * okyv, cgx, cgy, float(divisor),
            *w4)
    wl, wr, wt, wb, off = w4
    return prob, counts, (lambda img, out: weighted_step(img, wl, wr, wt, wb, off, out)), kind


@kernel
def _fill_missing(i0, v0, gx, gy, vx, vy, fallback, out):
    """I^(0) where the primal is missing: the mean of the neighbour identities I_q + <I_p - I_q>
    whose neighbour primal and gradient are both valid, else the channel's fallback value."""
    h, w, c = i0.shape
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                if v0[y, x, k] > 0.0:
                    out[y, x, k] = i0[y, x, k]
                    continue
                s = 0.0
                n = 0
                if x > 0 and v0[y, x - 1, k] > 0.0 and vx[y, x - 1, k] > 0.0:
                    s += i0[y, x - 1, k] + gx[y, x - 1, k]
                    n += 1
                if x + 1 < w and v0[y, x + 1, k] > 0.0 and vx[y, x, k] > 0.0:
                    s += i0[y, x + 1, k] - gx[y, x, k]
                    n += 1
                if y > 0 and v0[y - 1, x, k] > 0.0 and vy[y - 1, x, k] > 0.0:
                    s += i0[y - 1, x, k] + gy[y - 1, x, k]
                    n += 1
                if y + 1 < h and v0[y + 1, x, k] > 0.0 and vy[y, x, k] > 0.0:
                    s += i0[y + 1, x, k] - gy[y, x, k]
                    n += 1
                out[y, x, k] = s / n if n > 0 else fallback[k]


def _start(prob):
    """I^(0): the primal; a missing primal pixel starts from its neighbours' identities (or its
    channel's mean over valid pixels when it has none)."""
    if prob.complete:
        return prob.primal.copy()
    i0, gx, gy, v0, vx, vy = prob.clean()
    n = v0.sum(axis=(0, 1))
    mean = np.where(n > 0, i0.sum(axis=(0, 1)) / np.maximum(n, 1), 0.0)
    out = np.empty_like(i0)
    _fill_missing(i0, v0, gx, gy, vx, vy, mean, out)
    return out


def _iterate(primal, gx, gy, iterations, variances, halves, divisor, pool=VARIANCE_POOL):
    """Generator: (prob, counts, kind) first, then (n, image, rms change) per iteration."""
    if int(iterations) != iterations or iterations < 0:
        raise ValueError(f"iterations = {iterations!r} must be an integer >= 0 (30-50 is typical)")
    prob, counts, step, kind = _setup(primal, gx, gy, variances, halves, divisor, pool)
    yield prob, counts, kind
    img = _start(prob)
    out = np.empty_like(img)
    yield 0, img, np.nan
    for n in range(1, int(iterations) + 1):
        ss = step(img, out)
        img, out = out, img
        yield n, img, float(np.sqrt(ss / img.size))


def control_variates(primal, gx, gy, iterations: int = 50, *, variances: dict | None = None,
                     halves: dict | None = None, iterate_variance_divisor: float = 5.0,
                     variance_pool: int = VARIANCE_POOL) -> Reconstruction:
    """Control-variate reconstruction: uniform (Eq. 14) or, given variances, weighted (Eq. 20-22).

    ``variances = {"primal": v0, "gx": vx, "gy": vy}`` (per-pixel variances of the three means,
    H x W or H x W x C) or ``halves = {"primal": (A, B), "gx": (A, B), "gy": (A, B)}`` (two
    independent half-buffers, variances estimated by :func:`variances_from_halves` and pooled
    over (2 * variance_pool + 1)^2 pixels, module docstring) select the weighted form.
    ``history[n-1]`` is the RMS change of iteration n, ``||I^(n) - I^(n-1)||`` over all pixels
    and channels (the fixed-point residual of Eq. 11).
    """
    t0 = time.perf_counter()
    gen = _iterate(primal, gx, gy, iterations, variances, halves, iterate_variance_divisor, variance_pool)
    prob, counts, kind = next(gen)
    hist = []
    img = None
    for n, img, res in gen:
        if n > 0:
            hist.append(res)
    bad = ~np.isfinite(img)
    if bad.any():                     # cannot happen with finite weights; never let it through
        counts["output_fallback"] = int(bad.sum())
        img = np.where(bad, prob.clean()[0], img)
    return Reconstruction(prob.finish(img.copy()), np.asarray(hist), "fixed-point residual (RMS)",
                          counts, int(iterations), {"solver": f"cv-{kind}",
                                                    "seconds": time.perf_counter() - t0})


@dataclass
class CVHistory:
    """Per-iteration record of a control-variate run, for the book's convergence plots.

    iteration  0..N;  residual  RMS change of iteration n (NaN at n = 0);
    error      RMS difference to ``reference`` per iteration (None without a reference);
    image      the final image.
    """
    iteration: np.ndarray
    residual: np.ndarray
    error: np.ndarray | None
    image: np.ndarray

    def plot(self, ax=None, label: str = "control variates"):
        """Log-scale plot of residual (and error) against the iteration number; returns the axes."""
        import matplotlib.pyplot as plt
        if ax is None:
            _, ax = plt.subplots(figsize=(5, 3))
        ax.semilogy(self.iteration[1:], self.residual[1:], label=f"{label}: change per iteration")
        if self.error is not None:
            ax.semilogy(self.iteration, self.error, label=f"{label}: RMS error vs reference")
        ax.set_xlabel("iteration n")
        ax.set_ylabel("RMS")
        ax.legend()
        return ax


def cv_history(primal, gx, gy, iterations: int = 50, reference=None, **kw) -> CVHistory:
    """Run :func:`control_variates` recording every iteration (keyword args as there)."""
    gen = _iterate(primal, gx, gy, iterations, kw.pop("variances", None), kw.pop("halves", None),
                   kw.pop("iterate_variance_divisor", 5.0), kw.pop("variance_pool", VARIANCE_POOL))
    if kw:
        raise TypeError(f"cv_history: unexpected arguments {sorted(kw)}")
    prob, _, _ = next(gen)
    ref = None
    if reference is not None:
        ref = np.asarray(reference, dtype=np.float64).reshape(prob.shape)
    its, res, err = [], [], []
    img = None
    for n, img, r in gen:
        its.append(n)
        res.append(r)
        if ref is not None:
            err.append(float(np.sqrt(np.mean((img - ref) ** 2))))
    return CVHistory(np.asarray(its), np.asarray(res), None if ref is None else np.asarray(err),
                     prob.finish(img.copy()))
