"""Are a gradient integrator's gradients unbiased? The statistical test of the replay chapter.

For each of ``n_seeds`` independent seeds a small image is rendered and, per pixel,
d = gx - (P[x+1] - P[x]) (likewise gy) is formed: the gradient minus the finite difference of the
*primal* of the same run (pt's own estimator: ``primal`` for gpt-replay, ``primal_base`` for gpt).
Both are unbiased for I[x+1] - I[x] when the shift is right, so E[d] = 0, whatever the scene. The
truth comes from the primal path tracer, not from the shifts under test. Three tests on the same
differences, each at the family-wise false-alarm rate ``FAMILY_ALPHA``:

* local: |t| of the mean of d per 2x2 block (channels averaged) below the Bonferroni bound for all
  blocks of gx and gy (Student t, n_seeds - 1 dof): a bias confined to a few pixels shows here;
* global: the projection of d on an independent path-traced pilot's gradients (a matched filter,
  :func:`projected_t`), three two-sided tests (gx, gy, both): a bias proportional to the gradients;
* omnibus: the mean t^2 over all blocks below ``OMNIBUS_MAX``: a bias spread thin over many blocks.

Used by tests/test_gpt.py, tests/test_gpt_replay.py and by the fuzzer's gradient mode
(:func:`gdlearn.crosscheck.fuzz.run_gradient_seed`), which runs it on random scenes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

BLOCK = 2
FAMILY_ALPHA = 1e-3
#: Under E[d] = 0, t^2 of Student's t with nu = 31 dof has mean nu/(nu-2) = 1.07 and variance 2.5, so
#: the mean over 128 blocks has sd 0.14 if blocks were independent. They are not quite (gx and gy
#: blocks share primal pixels); allowing a 4x variance inflation (sd 0.28), 2.0 is still 3.3 sd above
#: the mean (one-sided p ~ 5e-4). Measured: 0.95 (Cornell box), 0.99 (caustics box).
OMNIBUS_MAX = 2.0


def blocks(a: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Sum over block x block pixel blocks of the channel mean of the (seeds, h, w, 3) array ``a``
    (blocks at the right / bottom edge may be smaller: every pixel is in exactly one block)."""
    a = a.mean(axis=-1)
    a = np.add.reduceat(a, np.arange(0, a.shape[1], block), axis=1)
    return np.add.reduceat(a, np.arange(0, a.shape[2], block), axis=2)


def differences(frames, primal: str = "primal"):
    """Per seed: d = gx - (P[x+1] - P[x]) and gy - (P[y+1] - P[y]) over the defined region (gx without
    its last column, gy without its last row). ``primal`` names the frame image P (``primal_base``:
    gpt's base radiance, pt's estimator, rather than its MIS primal)."""
    p = np.stack([f.primal if primal == "primal" else f.images[primal] for f in frames])
    gx = np.stack([f.gx for f in frames])
    gy = np.stack([f.gy for f in frames])
    return gx[:, :, :-1] - (p[:, :, 1:] - p[:, :, :-1]), gy[:, :-1, :] - (p[:, 1:, :] - p[:, :-1, :])


def t_abs(samples: np.ndarray) -> np.ndarray:
    """|t| of the mean of ``samples`` (axis 0 = seeds) against 0."""
    se = samples.std(axis=0, ddof=1) / np.sqrt(len(samples))
    return np.abs(samples.mean(axis=0)) / np.maximum(se, 1e-300)


def block_t(dx, dy, alpha: float = FAMILY_ALPHA):
    """|t| per block for gx and gy, and the Bonferroni threshold k for their number."""
    tx, ty = t_abs(blocks(dx)), t_abs(blocks(dy))
    k = stats.t.isf(alpha / (2 * (tx.size + ty.size)), df=len(dx) - 1)
    return tx, ty, k


def omnibus(tx, ty) -> float:
    """Mean t^2 over all blocks of gx and gy (see ``OMNIBUS_MAX``)."""
    return float(np.mean(np.concatenate([tx.ravel(), ty.ravel()]) ** 2))


def projected_t(dx, dy, pilot, alpha: float = FAMILY_ALPHA, robust: bool = False):
    """|t| of the per-seed scalars sum(d * v) over gx, over gy and over both; and their threshold.

    A wrong weight biases every gradient in proportion to itself (E[d] = c dI). Projecting d on
    v = dI / (var(dI) + median var), computed from an *independent* path-traced pilot frame (its
    finite differences and half-buffer variances: a matched filter), adds that bias up coherently
    over the whole image, far more power than any one block. Under a correct shift E[d] = 0 in
    every pixel, so each projection has mean 0 whatever the pilot. ``robust``: the regulariser
    max(median, mean, 1e-12) of the variances, which stays positive where most pixels are black (a
    caustic alone, a random scene), instead of their median."""
    p, v = pilot.primal.mean(axis=-1), pilot.variance().mean(axis=-1)
    vx, vy = v[:, 1:] + v[:, :-1], v[1:, :] + v[:-1, :]
    allv = np.concatenate([vx.ravel(), vy.ravel()])
    reg = max(np.median(allv), np.mean(allv), 1e-12) if robust else np.median(allv)
    px, py = (p[:, 1:] - p[:, :-1]) / (vx + reg), (p[1:, :] - p[:-1, :]) / (vy + reg)
    sx = (dx.mean(axis=-1) * px).sum(axis=(1, 2))
    sy = (dy.mean(axis=-1) * py).sum(axis=(1, 2))
    k = stats.t.isf(alpha / (2 * 3), df=len(dx) - 1)
    return float(t_abs(sx)), float(t_abs(sy)), float(t_abs(sx + sy)), k


@dataclass
class GradientCheck:
    """The three tests' statistics and bounds (see the module docstring)."""
    t_block: float
    k_block: float
    omnibus: float
    t_projected: float
    k_projected: float

    @property
    def ok(self) -> bool:
        return self.t_block < self.k_block and self.omnibus < OMNIBUS_MAX and self.t_projected < self.k_projected

    def summary(self) -> str:
        return (f"{'OK' if self.ok else 'BIASED'}: max block |t| {self.t_block:.2f} (bound {self.k_block:.2f}), "
                f"mean t^2 {self.omnibus:.2f} (bound {OMNIBUS_MAX}), projected |t| {self.t_projected:.2f} "
                f"(bound {self.k_projected:.2f})")


def check(frames, pilot, primal: str = "primal") -> GradientCheck:
    """Run the three tests on ``frames`` (one per independent seed) against a ``pilot`` pt frame of the
    same scene rendered with a seed none of the frames uses (robust projection: any scene)."""
    dx, dy = differences(frames, primal)
    tx, ty, k = block_t(dx, dy)
    px, py, pxy, kp = projected_t(dx, dy, pilot, robust=True)
    # an undefined t (0/0: no light in a block for every seed) is 0, not a failure
    tmax = float(np.nan_to_num(max(tx.max(), ty.max()), nan=0.0))
    return GradientCheck(tmax, float(k), omnibus(np.nan_to_num(tx), np.nan_to_num(ty)),
                         float(np.nan_to_num(max(px, py, pxy), nan=0.0)), float(kp))


def render_check(scene, integrator: str, *, n_seeds: int = 32, spp: int = 8, pilot_spp: int = 128,
                 seed0: int = 1000, pilot_seed: int = 7, threads: int | None = None,
                 broken: int = 0) -> GradientCheck:
    """Render ``scene`` with ``integrator`` (gpt or gpt-replay) at ``n_seeds`` seeds of ``spp`` each
    and check its gradients against the primal of the same runs (:func:`check`). ``broken``: a planted
    bug of :mod:`gdlearn.integrators.path.gpt_surface.vertex` (``BROKEN_*``, gpt only), to show the
    check can fail."""
    from gdlearn.integrators import make, render
    frames = []
    for s in range(n_seeds):
        integ = make(integrator, scene, seed=seed0 + s, spp_per_pass=spp, threads=threads)
        if broken:
            integ.broken = broken
        frames.append(render(integ, spp=spp))
    pilot = render(make("pt", scene, seed=pilot_seed, spp_per_pass=pilot_spp // 4, threads=threads),
                   spp=pilot_spp)
    return check(frames, pilot, "primal_base" if integrator == "gpt" else "primal")
