"""Reference images for error measurement: long runs cached on disk, Mitsuba 3 renders, files.

A convergence plot is only as good as its reference. The papers render theirs with a trusted
estimator for much longer than the compared runs (Gruson et al. 2018 §6: "The reference images are rendered
using BRE with a ..."). gdlearn does the same, and keeps the reference's own noise in view:

* :func:`render_reference` -- a long run of a gdlearn estimator (default ``pt``), cached in
  ``$GDLEARN_CACHE/references`` (default ``~/.cache/gdlearn/references``) under a key made of the
  scene's *content* (the file and every file it references), the estimator, spp, seed, options and
  gdlearn's source (:func:`!gdlearn.source_hash`): editing the scene or any of gdlearn's code never
  reuses a stale image.
* :func:`mitsuba_reference` -- Mitsuba 3 renders over several seeds (via
  :func:`!gdlearn.crosscheck.mitsuba.mitsuba_mean_stderr`), an estimator written by other people.
* :func:`load_reference` -- an image file (``.npz`` from this cache, ``.npy``, ``.exr``).

Every :class:`Reference` carries a per-pixel variance estimate when one is known (the two
half-buffers of a gdlearn frame; the spread over Mitsuba seeds) and its :attr:`Reference.floor`:
the relMSE a *perfect* image would show against it (:func:`gdlearn.experiments.metrics.relmse_floor`).
Curves flatten there, whatever the method; plots draw it as a line.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gdlearn.experiments import metrics

#: Bump when the cached file layout or the meaning of a key changes.
CACHE_FORMAT = 1


@dataclass
class Reference:
    image: np.ndarray                        # H x W x 3, linear RGB
    variance: np.ndarray | None = None       # per-pixel variance of ``image`` (None if unknown)
    spp: int | None = None
    estimator: str = "file"
    key: str = ""
    path: Path | None = None

    @property
    def floor(self) -> float:
        """Expected relMSE of a perfect image against this reference (NaN if the noise is unknown)."""
        if self.variance is None:
            return float("nan")
        return metrics.relmse_floor(self.variance, self.image)

    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = json.dumps({"spp": self.spp, "estimator": self.estimator, "key": self.key,
                           "format": CACHE_FORMAT})
        arrays = {"image": self.image, "meta": np.array(meta)}
        if self.variance is not None:
            arrays["variance"] = self.variance
        # A name of this save's own: two processes rendering the same reference at once (pytest-xdist
        # workers, a chapter's kernel) must not write into, or move away, one another's file.
        tmp = path.with_name(f"{path.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp.npz")
        try:
            np.savez_compressed(tmp, **arrays)
            os.replace(tmp, path)            # atomic: a concurrent reader never sees half a file
        finally:
            tmp.unlink(missing_ok=True)
        self.path = path
        return path


def cache_dir() -> Path:
    root = os.environ.get("GDLEARN_CACHE") or Path.home() / ".cache" / "gdlearn"
    return Path(root) / "references"


def scene_digest(scene) -> str:
    """SHA-256 of a scene's content: a file and the files its ``filename="..."`` attributes name
    (meshes, textures), or the ``repr`` of a scene object (e.g. a toy scene dataclass)."""
    h = hashlib.sha256()
    if hasattr(scene, "path") and hasattr(scene, "defaults"):     # a study.SceneFile
        h.update(repr(sorted(scene.defaults)).encode())
        scene = scene.path
    if isinstance(scene, (str, Path)):
        path = Path(scene)
        data = path.read_bytes()
        h.update(data)
        for name in sorted(set(re.findall(rb'filename\s*=\s*"([^"]+)"', data))):
            dep = path.parent / name.decode()
            h.update(name)
            h.update(dep.read_bytes() if dep.is_file() else b"<missing>")
    else:
        h.update(repr(scene).encode())
    return h.hexdigest()


def source_digest(sources=None) -> str:
    """A hash of gdlearn's sources: all of them (:func:`!gdlearn.source_hash`), or only ``sources``,
    files and folders named relative to the package (``("kernels", "integrators/path/pt.py")``).

    A long reference keyed by the sources its image depends on survives edits elsewhere (a shift, a
    photon estimator), so runs before and after such an edit are judged against the same image."""
    from gdlearn import source_hash
    if sources is None:
        return source_hash()
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for name in sorted(sources):
        path = root / name
        if not path.exists():
            raise FileNotFoundError(f"source {name!r} is not in gdlearn ({root}); name files or folders "
                                    "relative to the package, e.g. 'kernels' or 'integrators/path/pt.py'")
        for f in ([path] if path.is_file() else sorted(path.rglob("*.py"))):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def cache_key(scene, estimator, spp: int, seed: int, sources=None, **options) -> str:
    from gdlearn import __version__
    parts = {"scene": scene_digest(scene), "estimator": str(estimator), "spp": int(spp),
             "seed": int(seed), "options": sorted((k, repr(v)) for k, v in options.items()),
             "version": __version__, "source": source_digest(sources), "format": CACHE_FORMAT}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:20]


def load_reference(path) -> Reference:
    """Read a reference image: ``.npz`` (this cache's format), ``.npy`` or ``.exr``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"reference file {path} does not exist; render one with "
                                "gdlearn.experiments.references.render_reference or pass another file")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with np.load(path) as z:
            meta = json.loads(str(z["meta"])) if "meta" in z else {}
            var = z["variance"] if "variance" in z else None
            return Reference(z["image"], var, meta.get("spp"), meta.get("estimator", "file"),
                             meta.get("key", ""), path)
    if suffix == ".npy":
        return Reference(np.load(path).astype(np.float64), path=path)
    if suffix == ".exr":
        return Reference(_read_exr(path), path=path)
    raise ValueError(f"cannot read reference {path}: use a .npz, .npy or .exr file")


def _read_exr(path) -> np.ndarray:
    import OpenEXR
    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        if "RGB" in ch:
            img = ch["RGB"].pixels
        elif all(c in ch for c in "RGB"):
            img = np.stack([ch[c].pixels for c in "RGB"], axis=-1)
        else:
            raise ValueError(f"{path}: no R, G, B channels (found {', '.join(ch)})")
    return np.asarray(img, dtype=np.float64)[..., :3]


def render_reference(scene, estimator="pt", spp: int = 1024, seed: int = 1_000_003,
                     spp_per_pass: int = 16, cache: bool = True, sources=None, **options) -> Reference:
    """A long run of a gdlearn estimator, cached on disk (see the module docstring).

    The default seed is far from the small seeds studies use, so the reference is independent of
    the runs it judges (sharing random numbers would correlate their errors and hide them).
    ``sources``: key the cache by these of gdlearn's sources only (:func:`source_digest`), not all.
    """
    from gdlearn.experiments.study import load_scene, make_integrator
    from gdlearn.integrators.base import render

    # the noise estimate (and so the floor) comes from the two half-buffers, which a single pass
    # fills with the same estimate: variance 0 would call a noisy reference perfect
    spp_per_pass = max(1, min(spp_per_pass, spp // 2))
    key = cache_key(scene, estimator, spp, seed, sources, spp_per_pass=spp_per_pass, **options)
    path = cache_dir() / f"{key}.npz"
    if cache and path.is_file():
        return load_reference(path)
    integ = make_integrator(estimator, load_scene(scene), seed, spp_per_pass, **options)
    frame = render(integ, spp=spp)
    if frame.interrupted:          # fewer samples than the key says: neither cached nor handed back
        raise KeyboardInterrupt
    ref = Reference(frame.primal, frame.variance() if frame.passes >= 2 else None, frame.spp,
                    getattr(integ, "name", str(estimator)), key)
    if cache:
        ref.save(path)
    return ref


def mitsuba_reference(path, spp: int = 1024, seeds=(101, 102, 103, 104), variant: str = "scalar_rgb",
                      cache: bool = True, **defaults) -> Reference:
    """Mitsuba 3's mean over ``seeds`` (``spp // len(seeds)`` each) with its variance (the squared
    standard error over seeds), cached like :func:`render_reference`. ``defaults`` override the
    file's ``<default>`` parameters (``res=64``, ``max_depth=8``)."""
    from gdlearn.crosscheck.mitsuba import mitsuba_mean_stderr

    if hasattr(path, "path") and hasattr(path, "defaults"):       # a study.SceneFile
        defaults = {**dict(path.defaults), **defaults}
        path = path.path
    seeds = list(seeds)
    per = max(1, spp // len(seeds))
    # Mitsuba renders the file itself: of gdlearn only the driver of its processes matters
    key = cache_key(path, f"mitsuba:{variant}", per * len(seeds), seeds[0], ("crosscheck/mitsuba.py",),
                    seeds=seeds, **defaults)
    out = cache_dir() / f"{key}.npz"
    if cache and out.is_file():
        return load_reference(out)
    mean, stderr = mitsuba_mean_stderr(path, per, seeds, variant, **defaults)
    ref = Reference(mean, stderr ** 2, per * len(seeds), f"mitsuba:{variant}", key)
    if cache:
        ref.save(out)
    return ref
