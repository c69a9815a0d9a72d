"""Figures of a study: convergence (log-log relMSE vs seconds with fitted slopes), equal-time image
grids with relMSE captions, relative-error maps, stage-cost bars, time-to-reach and ratio bars.

Every function draws into a given matplotlib ``Axes`` (or creates a figure) and returns it, so the
book and ``gdlearn compare --plot`` compose the same pieces. Inputs are a
:class:`~gdlearn.experiments.study.Study` (tidy records) and plain arrays.
"""
from __future__ import annotations

import numpy as np

from gdlearn.experiments import metrics


def _plt():
    import matplotlib.pyplot as plt
    return plt


def _axes(ax, figsize=(5, 4)):
    if ax is not None:
        return ax
    return _plt().subplots(figsize=figsize)[1]


def display(image, exposure: float = 1.0) -> np.ndarray:
    """Linear RGB -> displayable sRGB-ish values in [0, 1] (clip, gamma 2.2). For figures only."""
    return np.clip(np.asarray(image) * exposure, 0.0, 1.0) ** (1 / 2.2)


def convergence(study, scene=None, metric: str = "relmse", ax=None, floor: bool = True,
                slope: bool = True):
    """log-log ``metric`` against seconds for every method (one line per seed, one colour per
    method), the fitted slope in the legend, and the reference's noise floor as a dashed line."""
    ax = _axes(ax)
    scene = scene or study.scenes()[0]
    colours = _plt().rcParams["axes.prop_cycle"].by_key()["color"]
    floors = []
    for i, m in enumerate(study.methods()):
        rs = study.select(method=m, scene=scene)
        rs = [r for r in rs if np.isfinite(r.get(metric, np.nan))]
        if not rs:
            continue
        c = colours[i % len(colours)]
        label = m
        if slope:
            s, _ = metrics.loglog_slope([r["seconds"] for r in rs], [r[metric] for r in rs])
            label = f"{m} (slope {s:.2f})"
        for j, sd in enumerate(dict.fromkeys(r["seed"] for r in rs)):
            cur = [r for r in rs if r["seed"] == sd]
            ax.loglog([r["seconds"] for r in cur], [r[metric] for r in cur], "o-", color=c, ms=3,
                      lw=1.2, alpha=1.0 if j == 0 else 0.4, label=label if j == 0 else None)
        floors += [r["relmse_floor"] for r in rs if np.isfinite(r.get("relmse_floor", np.nan))]
    if floor and floors and metric.startswith("relmse") and np.mean(floors) > 0:
        ax.axhline(float(np.mean(floors)), color="k", ls="--", lw=1,
                   label="reference noise floor")
    from matplotlib.ticker import NullFormatter
    ax.xaxis.set_minor_formatter(NullFormatter())    # short ranges would label every minor tick
    ax.set_xlabel("time (s, JIT compile excluded)")
    ax.set_ylabel(metric)
    ax.set_title(f"{scene}: {metric} vs time")
    ax.legend(fontsize=8)
    return ax


def image_grid(images: dict, reference=None, exposure: float = 1.0, axes=None, title_prefix=""):
    """One panel per ``label -> image`` (and the reference last), relMSE in each caption."""
    plt = _plt()
    n = len(images) + (reference is not None)
    if axes is None:
        _, axes = plt.subplots(1, n, figsize=(3 * n, 3), squeeze=False)
        axes = axes[0]
    for ax, (label, img) in zip(axes, images.items()):
        ax.imshow(display(img, exposure))
        cap = f"{title_prefix}{label}"
        if reference is not None:
            cap += f"\nrelMSE {metrics.relmse(img, reference):.3g}"
        ax.set_title(cap, fontsize=9)
        ax.axis("off")
    if reference is not None and len(axes) > len(images):
        axes[len(images)].imshow(display(reference, exposure))
        axes[len(images)].set_title("reference", fontsize=9)
        axes[len(images)].axis("off")
    return axes


def error_maps(images: dict, reference, axes=None, vmin: float = 1e-4, vmax: float = 1.0):
    """Per-pixel relative squared error (R - I)^2 / (R^2 + 0.001) on a shared log colour scale."""
    plt = _plt()
    from matplotlib.colors import LogNorm
    n = len(images)
    if axes is None:
        fig, axes = plt.subplots(1, n, figsize=(3 * n + 0.6, 3), squeeze=False)
        axes = axes[0]
    im = None
    for ax, (label, img) in zip(axes, images.items()):
        err = np.clip(metrics.relmse_map(img, reference), vmin, vmax)
        im = ax.imshow(err, norm=LogNorm(vmin=vmin, vmax=vmax), cmap="inferno")
        ax.set_title(f"{label}: relative error", fontsize=9)
        ax.axis("off")
    if im is not None:
        axes[0].figure.colorbar(im, ax=list(axes), shrink=0.8)
    return axes


def stage_bars(study, scene=None, ax=None):
    """Stacked bars: mean seconds per stage (trace, shift, gather, reconstruct, ...) at the end of
    each method's runs; the JIT compile time is written next to each bar, not stacked."""
    ax = _axes(ax)
    scene = scene or study.scenes()[0]
    methods = study.methods()
    finals = {m: study.select(True, method=m, scene=scene) for m in methods}
    stages = list(dict.fromkeys(k for rs in finals.values() for r in rs for k in r
                                if k.startswith("t_")))
    bottom = np.zeros(len(methods))
    for st in stages:
        vals = np.array([np.mean([r.get(st, 0.0) or 0.0 for r in finals[m]]) for m in methods])
        ax.bar(methods, vals, bottom=bottom, label=st[2:])
        bottom += vals
    # Stages an integrator does not time separately: the rest of the wall time.
    other = np.array([np.mean([r["seconds"] for r in finals[m]]) for m in methods]) - bottom
    if np.any(other > 1e-3 * max(bottom.max(), 1e-9)):
        ax.bar(methods, np.maximum(other, 0), bottom=bottom, label="other", color="0.8")
    for i, m in enumerate(methods):
        comp = np.mean([r["compile_seconds"] for r in finals[m]])
        ax.annotate(f"JIT {comp:.2f} s", (i, 0), xytext=(0, -22), textcoords="offset points",
                    ha="center", fontsize=7)
    ax.set_ylabel("seconds")
    ax.set_title(f"{scene}: time per stage")
    ax.legend(fontsize=8)
    return ax


def time_to_reach_bars(study, target: float, scene=None, ax=None, metric: str = "relmse"):
    """Mean time each method needs to reach ``metric <= target`` (missing bar: never reached)."""
    ax = _axes(ax)
    scene = scene or study.scenes()[0]
    ttr = study.time_to_reach(target, metric)
    methods = study.methods()
    vals = [np.nanmean([v for (m, s, _), v in ttr.items() if m == meth and s == scene] or [np.nan])
            for meth in methods]
    ax.bar(methods, np.nan_to_num(vals, nan=0.0))
    for i, v in enumerate(vals):
        ax.annotate("never" if not np.isfinite(v) else f"{v:.3g} s", (i, np.nan_to_num(v)),
                    ha="center", va="bottom", fontsize=8)
    ax.set_ylabel("seconds")
    ax.set_title(f"{scene}: time to reach {metric} {target:g}")
    return ax


def ratio_bars(study, baseline: str, scene=None, ax=None, metric: str = "relmse"):
    """Equal-time error ratios baseline / method (> 1: the method beats the baseline)."""
    ax = _axes(ax)
    scene = scene or study.scenes()[0]
    ratios = study.equal_time_ratios(baseline, metric)
    methods = study.methods()
    vals = [ratios[(m, scene)] for m in methods]
    ax.bar(methods, vals)
    ax.axhline(1.0, color="k", lw=0.8)
    for i, v in enumerate(vals):
        ax.annotate(f"{v:.2f}x", (i, v), ha="center", va="bottom", fontsize=8)
    ax.set_ylabel(f"{metric}({baseline}) / {metric}(method)")
    ax.set_title(f"{scene}: equal-time error ratio")
    return ax


def summary(study, scene=None, reference=None, baseline=None, metric: str = "relmse"):
    """The figure of ``gdlearn compare --plot``: convergence, stage costs, ratios, final images
    (first seed) and their error maps."""
    plt = _plt()
    scene = scene or study.scenes()[0]
    methods = study.methods()
    images = {m: study.images[(m, scene, min(s for (mm, sc, s) in study.images
                                             if mm == m and sc == scene))] for m in methods}
    has_ref = reference is not None
    n = max(3, len(methods) + has_ref)
    fig = plt.figure(figsize=(3.2 * n, 3.2 * (3 if has_ref else 2)), layout="constrained")
    grid = fig.add_gridspec(3 if has_ref else 2, n)
    if has_ref:
        convergence(study, scene, metric, ax=fig.add_subplot(grid[0, 0]))
        ratio_bars(study, baseline or methods[0], scene, fig.add_subplot(grid[0, 2]), metric)
    stage_bars(study, scene, fig.add_subplot(grid[0, 1]))
    image_grid(images, reference, axes=[fig.add_subplot(grid[1, i])
                                        for i in range(len(images) + has_ref)])
    if has_ref:
        error_maps(images, reference, axes=[fig.add_subplot(grid[2, i]) for i in range(len(images))])
    return fig
