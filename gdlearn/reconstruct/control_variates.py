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

Variances from two half-buffers (``halves=``) are pooled over each pixel's 3 x 3 window
(``variance_pool=1``, :func:`gdlearn.reconstruct.conventions.variances_from_halves`): each estimate
becomes the larger of itself and its window's median (primal) or mean (gradients). The per-pixel
estimate (A - B)^2 / 4 has one degree of freedom: in a pixel whose two halves happen to agree it is
near zero, Eq. 21 then trusts that pixel's identities almost alone, and the early snapshots of a
progressive render can end up worse than the primal image. A window is far steadier; the maximum
with the pixel's own estimate keeps an isolated noisy pixel (a firefly, the light's edge) from
being averaged into trust; and the primal's window takes the median because a pixel's variance
jumps with the image at a light's rim -- a mean there lends the dark pixels beside a light the
light's variance, weights them nearly uniformly and spreads the light's noise (the accuracy
chapter's toy image: relMSE 4.2e-3 with means everywhere, *worse* than the primal's 3.7e-3; 4.5e-5
with the median). Measured (2026-12-01, relMSE against an exact image or a 2048-spp pt reference,
mean over seeds), per-pixel -> means everywhere -> median for the primal, means for the gradients:
toy image 96 x 64, 6 seeds, 16 spp 1.0e-2 -> 7.6e-2 -> 6.7e-4, 256 spp 1.1e-4 -> 4.2e-3 -> 4.5e-5;
gpt-replay at 48^2, 4 seeds: Cornell box 4 spp 0.124 -> 0.039 -> 0.031, 16 spp 2.5e-2 -> 1.3e-2 ->
7.7e-3, 64 spp 1.8e-2 -> 4.2e-3 -> 2.2e-3 (primal 1.2e-2); fog box 4 spp 0.36 -> 0.083 -> 0.055,
64 spp 7.6e-3 -> 8.4e-3 -> 6.0e-3 (primal 5.0e-2); caustics box 16 spp 0.118 -> 0.093 -> 0.072,
64 spp 3.3e-2 -> 3.0e-2 -> 2.5e-2 (primal 0.10). Medians everywhere lost at 4 spp (Cornell 0.11,
caustics 0.58); a 5 x 5 window (plain means) was worse than 3 x 3 everywhere measured.
Explicit ``variances=`` are used as given.

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

from ._jit import kernel

from .conventions import Reconstruction, expand_like, prepare, variances_from_halves

#: window radius over which variances estimated from half-buffers are averaged (module docstring)
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


@njit(cache=True)
def _normalise(s, present, out):
    """Eq. 21 for one pixel: w_q = s_q^-2 / sum_r s_r^-2 over the present terms, computed as
    (m / s_q) / sum (m / s_r) with m = min s so that zero variances (exact terms) and variances
    from 1e-12 to 1e12 neither divide by zero nor overflow."""
    m = np.inf
    for i in range(5):
        if present[i] and s[i] < m:
            m = s[i]
    total = 0.0
    for i in range(5):
        if not present[i]:
            out[i] = 0.0
        elif m > 0.0:
            out[i] = m / s[i]
        else:
            out[i] = 1.0 if s[i] == 0.0 else 0.0
        total += out[i]
    for i in range(5):
        out[i] = out[i] / total if total > 0.0 else (1.0 if i == 0 else 0.0)


@kernel
def _weights(v0, vx, vy, ok0, okx, oky, gx, gy, divisor, wl, wr, wt, wb, off):
    """Normalised Eq. 21-22 weights of the four neighbour identities and the constant part
    off_p = sum_q w_pq <I_p - I_q>. The self weight is 1 - (wl + wr + wt + wb)."""
    h, w, c = v0.shape
    for y in prange(h):
        s = np.empty(5)
        present = np.zeros(5, dtype=np.bool_)
        ws = np.empty(5)
        for x in range(w):
            for k in range(c):
                vp = v0[y, x, k] / divisor
                s[0] = vp
                present[0] = ok0[y, x, k] > 0.0
                present[1] = x > 0 and okx[y, x - 1, k] > 0.0
                s[1] = vp + vx[y, x - 1, k] if x > 0 else 0.0
                present[2] = okx[y, x, k] > 0.0
                s[2] = vp + vx[y, x, k]
                present[3] = y > 0 and oky[y - 1, x, k] > 0.0
                s[3] = vp + vy[y - 1, x, k] if y > 0 else 0.0
                present[4] = oky[y, x, k] > 0.0
                s[4] = vp + vy[y, x, k]
                _normalise(s, present, ws)
                wl[y, x, k] = ws[1]
                wr[y, x, k] = ws[2]
                wt[y, x, k] = ws[3]
                wb[y, x, k] = ws[4]
                o = -ws[2] * gx[y, x, k] - ws[4] * gy[y, x, k]
                if x > 0:
                    o += ws[1] * gx[y, x - 1, k]
                if y > 0:
                    o += ws[3] * gy[y - 1, x, k]
                off[y, x, k] = o


@kernel
def _weighted_step(img, wl, wr, wt, wb, off, out):
    """One Eq. 20 iteration with precomputed weights; returns the sum of squared changes."""
    h, w, c = img.shape
    rows = np.zeros(h)
    for y in prange(h):
        for x in range(w):
            for k in range(c):
                ic = img[y, x, k]
                v = ic + off[y, x, k]
                if x > 0:
                    v += wl[y, x, k] * (img[y, x - 1, k] - ic)
                if x + 1 < w:
                    v += wr[y, x, k] * (img[y, x + 1, k] - ic)
                if y > 0:
                    v += wt[y, x, k] * (img[y - 1, x, k] - ic)
                if y + 1 < h:
                    v += wb[y, x, k] * (img[y + 1, x, k] - ic)
                d = v - ic
                rows[y] += d * d
                out[y, x, k] = v
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
    _weights(v0, vx, vy, valid0 * ok0v, validx * okxv, validy * okyv, cgx, cgy, float(divisor),
             *w4)
    wl, wr, wt, wb, off = w4
    return prob, counts, (lambda img, out: _weighted_step(img, wl, wr, wt, wb, off, out)), kind


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
