"""The book's interactive views: compare images, watch a progressive render, explore a parameter.

Every view here is built from stock ipywidgets (``Stack``, ``ToggleButtons``, ``IntSlider``,
``SelectionSlider``, ``Play``, ``Image``, ``HTML``) wired together with ``jslink``, and every image
is computed *before* the view is shown. Nothing calls back into Python when the reader moves a
slider, so the stored widget state in the built HTML is the whole view: it keeps working offline,
without a kernel (the book vendors @jupyter-widgets/html-manager; see book/_vendor/VENDORED.txt).
Matplotlib renders the pictures (PNG bytes inside ``Image`` widgets).

* :func:`compare_images` -- flip (buttons or slider) between methods; relMSE against a reference and
  the per-pixel relMSE map (the papers' metric, :mod:`gdlearn.experiments.metrics`).
* :func:`progressive_viewer` -- step or play through the frames of a progressive render.
* :func:`parameter_explorer` -- precompute ``fn`` over a small grid of parameters and browse it.
"""
from __future__ import annotations

import io
from typing import Callable, Mapping, Sequence

import numpy as np

from gdlearn.io.tonemap import tonemap

#: Largest number of pictures one view may precompute (each is stored in the page).
MAX_VIEWS = 64
#: Pictures narrower than this (pixels) are enlarged by pixel replication so noise stays visible.
MIN_DISPLAY = 256


# -- pictures -----------------------------------------------------------------------------------------
def srgb(image, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB (H x W x 3 or H x W) -> 8-bit sRGB for display: :func:`gdlearn.io.tonemap.tonemap`
    (scale by 2^exposure, clip to [0, 1], IEC 61966-2-1 curve; NaN/Inf show as black)."""
    return tonemap(image, exposure)


def _enlarge(rgb8: np.ndarray) -> np.ndarray:
    k = max(1, -(-MIN_DISPLAY // max(rgb8.shape[1], 1)))      # ceil: nearest-neighbour factor
    return np.repeat(np.repeat(rgb8, k, axis=0), k, axis=1)


def png(image, exposure: float = 0.0) -> bytes:
    """PNG bytes of a linear-RGB image (tone-mapped by :func:`srgb`, enlarged for small renders)."""
    import matplotlib.image as mpimg

    buf = io.BytesIO()
    mpimg.imsave(buf, _enlarge(srgb(image, exposure)), format="png")
    return buf.getvalue()


def _figure_png(fig) -> bytes:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def error_map_png(image, reference) -> bytes:
    """The per-pixel relMSE map (log10 scale, with a colour bar) as PNG bytes."""
    import matplotlib.pyplot as plt

    from gdlearn.experiments.metrics import relmse_map

    err = relmse_map(image, reference)
    fig, ax = plt.subplots(figsize=(3.2, 2.6))
    shown = ax.imshow(np.log10(np.maximum(err, 1e-8)), cmap="magma", vmin=-6, vmax=1,
                      interpolation="nearest")
    ax.set_axis_off()
    fig.colorbar(shown, ax=ax, label="log10 relMSE per pixel")
    return _figure_png(fig)


def _picture(value, exposure: float):
    """An ``Image`` widget for an H x W x 3 array, a matplotlib Figure, or PNG bytes."""
    import ipywidgets as w

    if isinstance(value, (bytes, bytearray)):
        data = bytes(value)
    elif hasattr(value, "savefig"):
        data = _figure_png(value)
    else:
        arr = np.asarray(value)
        if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
            raise ValueError(f"expected an H x W x 3 (or H x W) image, got shape {arr.shape}; pass "
                             "frame.primal, not the Frame, or return an image/Figure from fn")
        data = png(arr, exposure)
    return w.Image(value=data, format="png")


# -- views --------------------------------------------------------------------------------------------
def compare_images(images: Mapping[str, np.ndarray], reference=None, *, exposure: float = 0.0,
                   title: str = ""):
    """Flip between methods' images; with a ``reference``, show each one's relMSE and error map.

    ``images`` maps a method name to an H x W x 3 linear-RGB image. The buttons and the slider
    select the method; both run in the browser (``jslink``), so the built book keeps them working.
    Returns the widget (display it, or leave it as a cell's last expression).
    """
    import ipywidgets as w

    from gdlearn.experiments.metrics import relmse

    if not images:
        raise ValueError("compare_images needs at least one image: {'name': HxWx3 array, ...}")
    names = list(images)
    if reference is not None:
        names.append("reference")
    if len(names) > MAX_VIEWS:
        raise ValueError(f"{len(names)} images exceed MAX_VIEWS={MAX_VIEWS}; compare fewer methods")
    slides, rows = [], []
    for name in names:
        img = reference if name == "reference" else images[name]
        parts = [_picture(img, exposure)]
        label = f"<b>{name}</b>"
        if reference is not None and name != "reference":
            err = relmse(img, reference)
            label += f" &nbsp; relMSE = {err:.3g}"
            rows.append(f"<tr><td>{name}</td><td style='text-align:right'>{err:.4g}</td></tr>")
            parts.append(w.Image(value=error_map_png(img, reference), format="png"))
        # wrap: image + error map must not overflow (and be clipped by) a narrow book column
        slides.append(w.VBox([w.HTML(label), w.HBox(parts, layout=w.Layout(flex_flow="row wrap"))]))
    stack = w.Stack(slides, selected_index=0)
    buttons = w.ToggleButtons(options=names, index=0, description="show")
    slider = w.IntSlider(value=0, min=0, max=len(names) - 1, description="flip",
                         readout=False, continuous_update=True)
    w.jslink((buttons, "index"), (stack, "selected_index"))
    w.jslink((slider, "value"), (buttons, "index"))
    head = [w.HTML(f"<b>{title}</b>")] if title else []
    if rows:
        head.append(w.HTML("<table><tr><th>method</th><th>relMSE</th></tr>" + "".join(rows)
                           + "</table>"))
    return w.VBox(head + [buttons, slider, stack])


def _frame_label(i: int, frame, reference) -> tuple[str, np.ndarray]:
    if getattr(frame, "image", None) is not None:         # an experiments.progressive Snapshot
        text = f"{frame.spp} spp, {frame.seconds:.2f} s"
        img = frame.image
    elif hasattr(frame, "primal"):                        # an integrators Frame
        text = f"pass {frame.passes}: {frame.spp} spp, {frame.elapsed:.2f} s"
        img = frame.primal
    else:
        text, img = f"frame {i}", frame
    if reference is not None:
        from gdlearn.experiments.metrics import relmse

        text += f", relMSE = {relmse(img, reference):.3g}"
    return text, img


def progressive_viewer(frames: Sequence, reference=None, *, exposure: float = 0.0,
                       interval_ms: int = 600):
    """Step (slider) or play (button) through a progressive render.

    ``frames``: :class:`~gdlearn.integrators.base.Frame` objects, snapshots of
    :func:`gdlearn.experiments.progressive.run` (``keep_images="all"``), or plain H x W x 3 images. Each frame is labelled with its samples
    per pixel and wall time, plus relMSE when a ``reference`` is given.
    """
    import ipywidgets as w

    frames = list(frames)
    if not frames:
        raise ValueError("progressive_viewer needs at least one frame")
    if len(frames) > MAX_VIEWS:
        raise ValueError(f"{len(frames)} frames exceed MAX_VIEWS={MAX_VIEWS}; keep every k-th frame")
    slides = []
    for i, frame in enumerate(frames):
        text, img = _frame_label(i, frame, reference)
        slides.append(w.VBox([w.HTML(text), _picture(img, exposure)]))
    stack = w.Stack(slides, selected_index=0)
    slider = w.IntSlider(value=0, min=0, max=len(frames) - 1, description="frame")
    play = w.Play(value=0, min=0, max=len(frames) - 1, interval=interval_ms)
    w.jslink((play, "value"), (slider, "value"))
    w.jslink((slider, "value"), (stack, "selected_index"))
    return w.VBox([w.HBox([play, slider]), stack])


def _grid(ranges: Mapping[str, Sequence]) -> list[tuple[str, list]]:
    if not ranges:
        raise ValueError("parameter_explorer needs at least one parameter: name=[values, ...]")
    grid = []
    for name, values in ranges.items():
        values = list(values)
        if not values:
            raise ValueError(f"parameter {name!r} has no values; give a list like {name}=[1, 2, 4]")
        grid.append((name, values))
    total = int(np.prod([len(v) for _, v in grid]))
    if total > MAX_VIEWS:
        raise ValueError(f"{total} parameter combinations exceed MAX_VIEWS={MAX_VIEWS}; "
                         "use fewer values per parameter")
    return grid


def parameter_explorer(fn: Callable, *, exposure: float = 0.0, **ranges):
    """Browse ``fn(**params)`` over a grid: ``parameter_explorer(render_at, spp=[1, 4, 16, 64])``.

    ``fn`` returns an H x W x 3 image, a matplotlib Figure or PNG bytes. All combinations are
    computed up front (at most :data:`MAX_VIEWS`); one slider per parameter picks its value. Several
    parameters nest one ``Stack`` per parameter, and each slider is linked to every stack of its
    level, so the view still works without a kernel.
    """
    import ipywidgets as w

    grid = _grid(ranges)
    names = [n for n, _ in grid]
    sliders = [w.SelectionSlider(options=[(str(v), v) for v in vals], index=0, description=n)
               for n, vals in grid]
    levels: list[list] = [[] for _ in grid]          # stacks of each nesting level

    def build(level: int, fixed: dict):
        name, values = grid[level]
        children = []
        for v in values:
            params = {**fixed, name: v}
            if level + 1 < len(grid):
                children.append(build(level + 1, params))
            else:
                caption = ", ".join(f"{k} = {params[k]}" for k in names)
                children.append(w.VBox([w.HTML(caption), _picture(fn(**params), exposure)]))
        stack = w.Stack(children, selected_index=0)
        levels[level].append(stack)
        return stack

    root = build(0, {})
    for slider, stacks in zip(sliders, levels):
        for stack in stacks:
            w.jslink((slider, "index"), (stack, "selected_index"))
    return w.VBox(sliders + [root])


__all__ = ["compare_images", "progressive_viewer", "parameter_explorer", "srgb", "png",
           "error_map_png", "MAX_VIEWS"]
