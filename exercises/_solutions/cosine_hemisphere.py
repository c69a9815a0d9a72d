"""Solution of the exercise "cosine-hemisphere" (exercises/cosine-hemisphere/README.md).

The two warps are gdlearn's own (``gdlearn.kernels.sampling``, Malley's method on Mitsuba 3's
concentric disk), so the solution and the package cannot disagree; only the estimator is written
out here, because gdlearn has no stand-alone irradiance estimator.
"""
import numpy as np

from gdlearn.kernels.sampling import cosine_hemisphere_pdf, square_to_cosine_hemisphere


def irradiance_estimate(sky, n: int, seed: int) -> float:
    """<E> = (1/N) sum sky(w_k) cos(theta_k) / p(w_k) with p = cos(theta) / pi (Hua et al. 2019,
    Eq. 2). The cosine cancels against the pdf, so each sample contributes pi * sky(w_k)."""
    rng = np.random.default_rng(seed)
    u = rng.random((n, 2))
    total = 0.0
    for u1, u2 in u:
        w = square_to_cosine_hemisphere(u1, u2)
        pdf = cosine_hemisphere_pdf(w)
        if pdf > 0.0:                      # a grazing sample (z = 0) has no contribution
            total += sky(w) * w[2] / pdf
    return total / n


__all__ = ["square_to_cosine_hemisphere", "cosine_hemisphere_pdf", "irradiance_estimate"]
