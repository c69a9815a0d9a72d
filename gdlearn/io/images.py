"""Image files: ``.exr`` (float32 RGB, OpenEXR package), ``.png`` (tone-mapped 8-bit sRGB, for
viewing), ``.npy`` (float64 H x W x 3, linear: the lossless choice for experiments).

``write_image(path, img)`` picks the format from the extension; ``read_image(path)`` returns linear
float64 H x W x 3 for all three (a PNG is sRGB-decoded, so only its clamped, quantised values come
back).
"""
from __future__ import annotations

import os

import numpy as np

from gdlearn.io.tonemap import srgb_decode, tonemap

FORMATS = (".exr", ".png", ".npy")


def _ext(path) -> str:
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in FORMATS:
        raise ValueError(f"cannot write/read {str(path)!r}: unknown image extension {ext or '(none)'!r}; "
                         f"fix: use one of {', '.join(FORMATS)}")
    return ext


def _as_rgb(img) -> np.ndarray:
    a = np.asarray(img, dtype=np.float64)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"an image must be H x W x 3 (or H x W), got shape {a.shape}")
    return a


def write_image(path, img, exposure: float = 0.0) -> None:
    """Write ``img`` (H x W x 3 linear RGB) to ``path`` (.exr / .png / .npy); folders are created."""
    ext = _ext(path)
    a = _as_rgb(img)
    d = os.path.dirname(os.path.abspath(str(path)))
    os.makedirs(d, exist_ok=True)
    if ext == ".npy":
        np.save(str(path), a)
    elif ext == ".png":
        import matplotlib.image as mpimg
        mpimg.imsave(str(path), tonemap(a, exposure))
    else:
        import OpenEXR
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, {"RGB": np.ascontiguousarray(a.astype(np.float32))}) as f:
            f.write(str(path))


def read_image(path) -> np.ndarray:
    """Read an image written by :func:`write_image` (or by Mitsuba) as linear float64 H x W x 3."""
    ext = _ext(path)
    if ext == ".npy":
        return _as_rgb(np.load(str(path)))
    if ext == ".png":
        import matplotlib.image as mpimg
        v = mpimg.imread(str(path))[..., :3]          # floats in [0, 1] for an 8-bit PNG
        return srgb_decode(v)
    import OpenEXR
    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        if "RGB" in ch:
            return _as_rgb(ch["RGB"].pixels)
        if all(c in ch for c in "RGB"):
            return np.stack([ch[c].pixels for c in "RGB"], axis=2).astype(np.float64)
        raise ValueError(f"{path}: no R, G, B channels (found {sorted(ch)})")
