"""Gradient error at equal samples and shift statistics: how good a shift mapping is, before any
reconstruction (the STAR's Fig. 5 comparison, Hua et al. 2019, §3.5; book chapter
"Gradient-domain path tracing", book/gpt.md).

A gradient estimator is unbiased whatever the shift (Hua et al. 2019, Eq. 16 with weights summing to one),
so shifts differ only in the *variance* of their gradients. At an equal number of samples per pixel
that variance is measured here as the error of the estimated forward differences gx, gy against the
forward differences of a long reference render:

    grad relMSE = mean over defined gradients and channels of (G - (R_q - R_p))^2 / (m_pq^2 + eps),
    m_pq = (R_p + R_q) / 2,

i.e. the squared gradient error relative to the brightness of the pixel pair, with the relMSE
epsilon of Gruson et al. 2018 §6 (:data:`gdlearn.experiments.metrics.RELMSE_EPS`). Normalising by the pair's
brightness rather than by the gradient itself keeps flat regions (reference gradient ~ 0) from
turning the metric into a plain MSE times 1/eps, and weighs errors as the reconstructed image will
show them: relative to brightness, like the image relMSE. Undefined gradients (the last column of
gx, the last row of gy) are excluded. An estimator without gradients (``pt``) is judged by the
finite differences of its primal image -- the baseline every shift must beat.

:func:`shift_summary` turns a frame's ``shift_<action>_{run,ok,failed}`` counters (integrator
``gpt``) into runs per base path and success rates.
"""
from __future__ import annotations

import time

import numpy as np

from gdlearn.integrators.base import render

from gdlearn.experiments.metrics import RELMSE_EPS
from gdlearn.experiments.study import Method, load_scene, make_integrator, scene_name

#: actions whose counters ``gpt`` frames carry (gdlearn.shifts.policy.ACTION_NAMES)
ACTIONS = ("replay", "halfvector", "reconnection", "manifold", "fail")


def finite_differences(image) -> tuple[np.ndarray, np.ndarray]:
    """Forward differences gx[y, x] = I[y, x+1] - I[y, x], gy[y, x] = I[y+1, x] - I[y, x] (the
    reconstruction's convention, gdlearn.reconstruct; undefined entries 0)."""
    from gdlearn.reconstruct.conventions import forward_differences
    return forward_differences(image)


def gradient_relmse_maps(gx, gy, reference, eps: float = RELMSE_EPS) -> tuple[np.ndarray, np.ndarray]:
    """Per-gradient relative squared errors (module docstring), averaged over channels: maps of
    shape (H, W-1) for gx and (H-1, W) for gy. Non-finite estimates count as +inf."""
    ref = np.asarray(reference, dtype=np.float64)
    gx, gy = np.asarray(gx, dtype=np.float64), np.asarray(gy, dtype=np.float64)
    if gx.shape != ref.shape or gy.shape != ref.shape:
        raise ValueError(f"gradient shapes {gx.shape}, {gy.shape} differ from the reference's {ref.shape}; "
                         "render the reference at the same resolution as the gradients")
    if not np.all(np.isfinite(ref)):
        raise ValueError("the reference contains NaN or Inf pixels; re-render it before measuring gradients")
    out = []
    for g, a, b in ((gx[:, :-1], ref[:, :-1], ref[:, 1:]), (gy[:-1], ref[:-1], ref[1:])):
        mid = 0.5 * (a + b)
        err = (g - (b - a)) ** 2 / (mid * mid + eps)
        err = np.where(np.isfinite(err), err, np.inf)
        out.append(err.mean(axis=-1) if err.ndim == 3 else err)
    return out[0], out[1]


def gradient_relmse(gx, gy, reference, eps: float = RELMSE_EPS) -> float:
    """Mean of :func:`gradient_relmse_maps` over all defined gradients of both directions."""
    ex, ey = gradient_relmse_maps(gx, gy, reference, eps)
    return float((ex.sum() + ey.sum()) / (ex.size + ey.size))


def frame_gradients(frame) -> tuple[np.ndarray, np.ndarray, bool]:
    """(gx, gy, shifted): the frame's estimated gradients, or the finite differences of its primal
    image (``shifted`` False) when the estimator produces none."""
    if frame.gx is not None and frame.gy is not None:
        return frame.gx, frame.gy, True
    gx, gy = finite_differences(frame.primal)
    return gx, gy, False


def shift_summary(stats: dict) -> dict[str, dict[str, float]]:
    """``{action: {"per_path": runs per base path, "success": ok / run (NaN if it never ran)}}`` from
    a frame's counters ``paths`` and ``shift_<action>_{run,ok}``. A shift is counted per offset
    path segment, so ``per_path`` sums over the four offsets and the vertices of each path."""
    paths = max(int(stats.get("paths", 0)), 1)
    out = {}
    for a in ACTIONS:
        run = int(stats.get(f"shift_{a}_run", 0))
        ok = int(stats.get(f"shift_{a}_ok", 0))
        if f"shift_{a}_run" in stats:
            out[a] = {"per_path": run / paths, "success": ok / run if run else float("nan")}
    return out


def summed_stats(records) -> dict[str, int]:
    """The frames' counters of ``records`` (their ``n_`` columns, written by :func:`gradient_errors`
    and :func:`~gdlearn.experiments.study.equal_time`), summed over the records, prefix removed: the
    ``stats`` :func:`shift_summary` reads, for several runs at once."""
    out = {}
    for r in records:
        for k, v in r.items():
            if k.startswith("n_"):
                out[k[2:]] = out.get(k[2:], 0) + v
    return out


def gradient_errors(methods, scenes, *, spp: int, seeds, references, spp_per_pass: int | None = None,
                    eps: float = RELMSE_EPS) -> list[dict]:
    """Render every method on every scene at ``spp`` samples per pixel for every seed and measure
    its gradients against the reference's finite differences (the STAR's Fig. 5 at equal samples).

    ``methods``: specs for :meth:`Method.parse <gdlearn.experiments.study.Method.parse>` (``"pt"``, ``"gpt-replay"``, or ``Method(label,
    "gpt", None, (("shift", policy),))``). ``scenes``: paths, :class:`~gdlearn.experiments.study.SceneFile` objects or scene objects.
    ``seeds``: a count (0..N-1) or a list. ``references``: scene name -> image or Reference.
    Returns one record per run: method, scene, seed, spp, shifted (False: finite differences of the
    primal), grad_relmse, gx_relmse, gy_relmse, seconds (render time, JIT excluded) and the
    frame's stats (prefixed ``n_``). Use :func:`summarize` for means and standard errors.
    """
    methods = [Method.parse(m) for m in methods]
    seeds = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
    records = []
    for sc in scenes:
        name = scene_name(sc)
        ref = references[name]
        ref = getattr(ref, "image", ref)
        scene = load_scene(sc)
        for m in methods:
            for sd in seeds:
                integ = make_integrator(m.estimator, scene, int(sd), spp_per_pass or spp, **dict(m.options))
                integ.warmup()
                t0 = time.perf_counter()
                frame = render(integ, spp=spp)
                seconds = time.perf_counter() - t0
                gx, gy, shifted = frame_gradients(frame)
                ex, ey = gradient_relmse_maps(gx, gy, ref, eps)
                rec = {"method": m.label, "scene": name, "seed": int(sd), "spp": frame.spp, "shifted": shifted,
                       "grad_relmse": float((ex.sum() + ey.sum()) / (ex.size + ey.size)),
                       "gx_relmse": float(ex.mean()), "gy_relmse": float(ey.mean()), "seconds": seconds}
                rec.update({f"n_{k}": v for k, v in frame.stats.items()})
                records.append(rec)
    return records


def summarize(records, metric: str = "grad_relmse") -> dict[tuple, dict[str, float]]:
    """(method, scene) -> {"mean", "stderr" (NaN for one seed), "n"} of ``metric`` over seeds."""
    groups: dict[tuple, list] = {}
    for r in records:
        groups.setdefault((r["method"], r["scene"]), []).append(r[metric])
    out = {}
    for key, vals in groups.items():
        v = np.asarray(vals, dtype=np.float64)
        se = float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")
        out[key] = {"mean": float(v.mean()), "stderr": se, "n": int(v.size)}
    return out
