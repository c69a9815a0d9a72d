"""Shared helpers for the kernel tests: a pbrt-style chi-squared goodness-of-fit test.

Samples are binned; expected counts come from integrating an independent density numerically
(Gauss-Legendre inside every bin); bins with expected count < 5 are pooled (Cochran's rule, as pbrt
and Mitsuba's chi2 tests do); the statistic's p-value must exceed ``alpha`` (1e-3 per test; the seeds
are fixed, so a pass is deterministic, and a wrong distribution gives p ~ 0 by a wide margin).
"""
import numpy as np
from scipy import stats

MIN_EXPECTED = 5.0


def chi2_pvalue(observed, expected, min_expected=MIN_EXPECTED):
    """p-value of Pearson's chi^2 after pooling low-expectation bins. Observations in a bin with
    (numerically) zero expectation make the test fail outright (p = 0)."""
    observed = np.asarray(observed, dtype=np.float64).ravel()
    expected = np.asarray(expected, dtype=np.float64).ravel()
    if np.any((expected <= 1e-12 * expected.sum()) & (observed > 0)):
        return 0.0
    order = np.argsort(expected)
    obs, exp = observed[order], expected[order]
    # pool the smallest bins (ascending expectation) until each pool has >= min_expected
    groups_o, groups_e = [], []
    acc_o = acc_e = 0.0
    for o, e in zip(obs, exp):
        acc_o += o
        acc_e += e
        if acc_e >= min_expected:
            groups_o.append(acc_o)
            groups_e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0 or acc_o > 0:
        if groups_e:                      # leftover tail: merge into the last group
            groups_o[-1] += acc_o
            groups_e[-1] += acc_e
        else:
            groups_o.append(acc_o)
            groups_e.append(acc_e)
    go, ge = np.array(groups_o), np.array(groups_e)
    dof = go.size - 1
    if dof < 1:
        return 1.0
    stat = float(np.sum((go - ge) ** 2 / ge))
    return float(stats.chi2.sf(stat, dof))


def gl_nodes(n):
    """Gauss-Legendre nodes / weights on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def sphere_bins(dirs, n_cos, n_phi):
    """Histogram of unit vectors over (cos theta in [-1, 1], phi in [0, 2 pi))."""
    c = np.clip(dirs[:, 2], -1.0, 1.0)
    phi = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2 * np.pi)
    i = np.minimum(((c + 1.0) * 0.5 * n_cos).astype(int), n_cos - 1)
    j = np.minimum((phi / (2 * np.pi) * n_phi).astype(int), n_phi - 1)
    h = np.zeros((n_cos, n_phi))
    np.add.at(h, (i, j), 1.0)
    return h


def sphere_grid(n_cos, n_phi, k):
    """Quadrature points over the same (cos, phi) bins: returns (dirs (n_cos*n_phi*k*k, 3), weights
    in steradians) ordered bin by bin, so ``(pdf * w).reshape(n_cos, n_phi, -1).sum(-1)`` is the
    probability of every bin."""
    x, w = gl_nodes(k)
    ci = (np.arange(n_cos)[:, None] + x[None, :]) / n_cos * 2.0 - 1.0          # (n_cos, k)
    pj = (np.arange(n_phi)[:, None] + x[None, :]) / n_phi * 2.0 * np.pi        # (n_phi, k)
    wc = w * (2.0 / n_cos)
    wp = w * (2.0 * np.pi / n_phi)
    C = ci[:, None, :, None] * np.ones((1, n_phi, 1, k))
    P = pj[None, :, None, :] * np.ones((n_cos, 1, k, 1))
    W = wc[None, None, :, None] * wp[None, None, None, :] * np.ones((n_cos, n_phi, 1, 1))
    s = np.sqrt(np.maximum(0.0, 1.0 - C * C))
    dirs = np.stack([s * np.cos(P), s * np.sin(P), C], axis=-1).reshape(-1, 3)
    return dirs, W.reshape(-1)
