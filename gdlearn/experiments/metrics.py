"""Error metrics for comparing an image I against a reference R: relMSE, MSE, trimmed relMSE.

The papers gdlearn follows all measure error with the *relative mean squared error*. Gruson et al.
2018 (Gruson et al. 2018, §6): "We use a relative mean square error metric relMSE= (1/n) sum (R - I)^2/(R^2 +
0.001), where R is the reference and I our rendered output." Hua et al. 2017 (Hua et al. 2017, §5) use the
same formula with "n is the number of pixels", and the STAR (Hua et al. 2019, §4.5) notes
"In the BOOKSHELF scene, we discarded 0.01% of the highest error pixels in the reconstructed image
[...] this only affects the metric, not the reconstruction itself" -- that is :func:`relmse_trimmed`.

The seeds do not say how colour channels enter. gdlearn applies the formula **per channel** (R^2
squares each channel of the reference, not a luminance) and **averages over channels** as well as
over pixels, so for an H x W x 3 image n = 3 H W terms. A grey image therefore has the same relMSE
as its single channel. The 0.001 keeps black reference pixels from dividing by zero; it also makes
the metric behave like a plain MSE (times 1000) where R^2 << 0.001, i.e. in the darkest pixels.

Why relative: the eye (and a tone mapper) judges errors relative to brightness, so an error of 0.1
on a pixel of value 10 matters as little as 0.001 on a pixel of value 0.1; a plain MSE is dominated
by the few brightest pixels (light sources, caustics). The book's chapter "What accuracy costs"
(book/accuracy.md) shows both on the same renders.
"""
from __future__ import annotations

import numpy as np

#: The epsilon of the papers' relMSE denominator R^2 + 0.001 (Gruson et al. 2018 §6, Hua et al. 2017 §5).
RELMSE_EPS = 1e-3
#: The fraction of highest-error pixels the STAR discards for one scene (Hua et al. 2019 §4.5: 0.01 %).
STAR_TRIM = 1e-4


def _check_pair(image, reference) -> tuple[np.ndarray, np.ndarray]:
    img = np.asarray(image, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    if img.shape != ref.shape:
        raise ValueError(f"image shape {img.shape} differs from reference shape {ref.shape}; "
                         "render the reference at the same resolution (film width/height) as the image")
    if not np.all(np.isfinite(ref)):
        raise ValueError("the reference contains NaN or Inf pixels; re-render or repair it before "
                         "measuring errors against it")
    return img, ref


def relmse_map(image, reference, eps: float = RELMSE_EPS) -> np.ndarray:
    """Per-pixel relative squared error (R - I)^2 / (R^2 + eps), averaged over channels: an H x W map.

    Non-finite image values count as an error of +inf (they must never be hidden by the metric).
    """
    img, ref = _check_pair(image, reference)
    err = (ref - img) ** 2 / (ref * ref + eps)
    err = np.where(np.isfinite(err), err, np.inf)
    return err.mean(axis=-1) if err.ndim == 3 else err


def relmse(image, reference, eps: float = RELMSE_EPS) -> float:
    """relMSE = (1/n) sum (R - I)^2 / (R^2 + 0.001) over pixels and channels (Gruson et al. 2018 §6)."""
    return float(relmse_map(image, reference, eps).mean())


def relmse_trimmed(image, reference, trim: float = STAR_TRIM, eps: float = RELMSE_EPS) -> float:
    """relMSE after discarding the fraction ``trim`` of pixels with the highest error (Hua et al. 2019 §4.5).

    Pixels are ranked by their channel-averaged error; ``floor(trim * H * W)`` of them are dropped
    (none on images smaller than 1 / trim pixels, so the trimmed value equals :func:`relmse` there).
    """
    if not 0.0 <= trim < 1.0:
        raise ValueError(f"trim={trim} must be a fraction in [0, 1), e.g. 1e-4 for the STAR's 0.01 %")
    err = np.sort(relmse_map(image, reference, eps).ravel())
    drop = int(np.floor(trim * err.size))
    return float(err[: err.size - drop].mean())


def mse(image, reference) -> float:
    """Plain mean squared error (1/n) sum (R - I)^2 over pixels and channels."""
    img, ref = _check_pair(image, reference)
    return float(np.mean((ref - img) ** 2))


def relmse_floor(reference_variance, reference, eps: float = RELMSE_EPS) -> float:
    """The relMSE a perfect image would show against a *noisy* reference.

    If R = T + e with E[e] = 0 and Var[e] = v per pixel and channel, then for an image I independent
    of R, E[(R - I)^2] = (T - I)^2 + v: the measured relMSE is the true one plus
    (1/n) sum v / (R^2 + eps). Convergence curves flatten at this floor however good the image is,
    so plots draw it (book/accuracy.md). ``reference_variance`` is e.g. ``Frame.variance()``.
    """
    var, ref = _check_pair(reference_variance, reference)
    return float(np.mean(var / (ref * ref + eps)))


def bias_variance(images, reference, eps: float = RELMSE_EPS, reference_variance=None, mask=None) -> dict[str, float]:
    """Split the mean per-seed relMSE of independent renders into a variance and a bias part.

    ``images`` are n >= 2 renders of one scene by one estimator with different seeds. Per pixel and
    channel, with m the mean of the n renders and s^2 their sample variance,
    mean_k (X_k - R)^2 = (m - R)^2 + (n - 1)/n s^2 exactly; (m - R)^2 - s^2/n estimates the squared
    bias (its expectation is (E X - R)^2) and s^2 the variance of one render. Weighted as relMSE
    weighs them and averaged (over ``mask``'s pixels, a boolean H x W array, if given),
    ``relmse = bias2 + variance`` holds exactly, where ``relmse`` is the mean of the renders' own
    relMSE. ``bias2`` includes the reference's own noise (the floor, :func:`relmse_floor`) unless
    its per-pixel ``reference_variance`` is given, which is then subtracted (E (m - R)^2 holds it
    once more for an independent noisy R), and ``relmse`` less it. ``bias2`` may come out slightly
    negative when the bias is below what n renders resolve: it is not clipped per pixel, which would
    leave a positive floor of pure noise. A kernel estimator's radius trades one part against the
    other (the photon chapters).
    """
    stack = np.asarray([_check_pair(im, reference)[0] for im in images], dtype=np.float64)
    if stack.shape[0] < 2:
        raise ValueError(f"bias_variance needs at least 2 independent renders, got {stack.shape[0]}; "
                         "render the same scene with more seeds")
    if not np.all(np.isfinite(stack)):
        raise ValueError("a render holds NaN or Inf pixels: its error is undefined; find the bad samples first")
    ref = np.asarray(reference, dtype=np.float64)
    w = 1.0 / (ref * ref + eps)
    n = stack.shape[0]
    s2 = stack.var(axis=0, ddof=1)
    sq = (stack.mean(axis=0) - ref) ** 2
    if reference_variance is not None:
        sq = sq - _check_pair(reference_variance, reference)[0]
    pick = (lambda a: a) if mask is None else (lambda a: a[np.asarray(mask, dtype=bool)])
    variance = float(np.mean(pick(s2 * w)))
    bias2 = float(np.mean(pick(sq * w))) - variance / n
    return {"relmse": bias2 + variance, "bias2": bias2, "variance": variance, "renders": n}


def loglog_slope(seconds, errors) -> tuple[float, float]:
    """Least-squares fit log(error) = slope * log(seconds) + intercept; returns (slope, intercept).

    An unbiased Monte Carlo estimator has variance ~ 1/N, hence relMSE ~ 1/time: slope -1 on a log-log
    plot. Points with non-positive or non-finite values are ignored; fewer than two points give NaN.
    """
    t = np.asarray(seconds, dtype=np.float64)
    e = np.asarray(errors, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(e) & (t > 0) & (e > 0)
    if ok.sum() < 2 or np.ptp(np.log(t[ok])) == 0.0:
        return float("nan"), float("nan")
    slope, intercept = np.polyfit(np.log(t[ok]), np.log(e[ok]), 1)
    return float(slope), float(intercept)


def time_to_reach(seconds, errors, target: float) -> float:
    """First time at which a convergence curve reaches ``error <= target``, interpolated log-log
    between the two snapshots around the crossing; NaN if the curve never gets there."""
    t = np.asarray(seconds, dtype=np.float64)
    e = np.asarray(errors, dtype=np.float64)
    below = np.nonzero(e <= target)[0]
    if below.size == 0:
        return float("nan")
    i = int(below[0])
    if i == 0 or e[i - 1] <= 0 or e[i] <= 0 or t[i - 1] <= 0:
        return float(t[i])
    # Between snapshots the curve is a straight line in log-log coordinates (a power law).
    f = (np.log(target) - np.log(e[i - 1])) / (np.log(e[i]) - np.log(e[i - 1]))
    return float(np.exp(np.log(t[i - 1]) + f * (np.log(t[i]) - np.log(t[i - 1]))))
