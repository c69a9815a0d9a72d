"""Per-photon kernel radii from the photon density: k-NN and the variable kernels of the BRE.

Jarosz et al. 2008, Sec. 4 ("Photon Radius Computation"): the beam radiance estimate gives every
photon its own radius before the hierarchy is built (:mod:`gdlearn.photons.bbh`). Two choices:

* k-NN: r_i = d_{i,n}, the distance from photon i to its n-th nearest other photon -- the radius
  a conventional k-NN estimate at the photon would use;
* variable kernels (VK): a pilot density from the m-th neighbour, m << n, extrapolated to n photons
  under a locally uniform 3D density, r_i = d_{i,m} (n / m)^(1/3) with m = round(sqrt(n)) by
  default. The paper's cube root, for a 3D density (PHOTONS.md E4: Mitsuba's ``bre.cpp`` uses a
  square root, which blurs 5.7 d_m instead of 3.2 d_m at n = 1000). m < 5 gives noisy radii.

The neighbour search is scipy's ``cKDTree`` (``workers`` threads). Duplicated positions are
other photons at distance 0, so radii are clamped below by ``r_min`` (default 1e-9 x the
diagonal of the photons' bounding box): a zero radius never reaches an estimator.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree


def _points(pos) -> np.ndarray:
    p = np.asarray(pos, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"pos must be an (n, 3) array of photon positions, not shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("pos holds non-finite coordinates; drop those photons first")
    return p


def knn_distance(pos, k: int, workers: int = 1) -> np.ndarray:
    """Distance from each photon to its k-th nearest *other* photon (the farthest one there is when
    fewer than k others exist; inf for a lone photon)."""
    p = _points(pos)
    if int(k) < 1:
        raise ValueError(f"k={k!r}: the neighbour rank must be >= 1")
    n = p.shape[0]
    if n <= 1:
        return np.full(n, math.inf)
    kk = min(int(k), n - 1) + 1                    # + 1: the photon itself comes first
    d, _ = cKDTree(p).query(p, k=kk, workers=workers)
    return np.asarray(d[:, -1], dtype=np.float64)


def _floor(p, r_min):
    if r_min is not None:
        return float(r_min)
    diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) if p.shape[0] else 0.0
    return 1e-9 * diag if diag > 0 else 1e-12


def knn_radii(pos, n_neighbors: int, workers: int = 1, r_min=None) -> np.ndarray:
    """r_i = d_{i,n}, clamped below at ``r_min`` (module docstring)."""
    if int(n_neighbors) < 1:
        raise ValueError(f"n_neighbors={n_neighbors!r}: pass the photon count a kernel should hold (>= 1)")
    p = _points(pos)
    return np.maximum(knn_distance(p, n_neighbors, workers), _floor(p, r_min))


def variable_radii(pos, n_neighbors: int, m=None, workers: int = 1, r_min=None) -> np.ndarray:
    """Jarosz et al. 2008, Sec. 4: r_i = d_{i,m} (n / m)^(1/3), m = round(sqrt(n)) by default."""
    n = int(n_neighbors)
    if n < 1:
        raise ValueError(f"n_neighbors={n_neighbors!r}: pass the photon count a kernel should hold (>= 1)")
    m = max(1, int(round(math.sqrt(n)))) if m is None else int(m)
    if m < 1:
        raise ValueError(f"m={m!r}: the pilot neighbour rank must be >= 1 (the paper advises >= 5)")
    p = _points(pos)
    return np.maximum(knn_distance(p, m, workers) * (n / m) ** (1.0 / 3.0), _floor(p, r_min))
