"""Render gdlearn's scene files with Mitsuba 3, the independent renderer gdlearn is checked against.

The shipped ``scenes/*.xml`` are a subset of Mitsuba 3's XML, so ``mitsuba.load_file`` reads them
unchanged; their ``<default>`` parameters (``res``, ``spp``, ``max_depth``) are overridden here as
keyword arguments, exactly as ``mi.load_file(path, res=32)`` does (Mitsuba 3 docs, "Scene XML file
format", section "Default parameters").

Two Mitsuba variants matter here:

* ``scalar_rgb``: one ray at a time on the CPU; works wherever the ``mitsuba`` wheel installs.
* ``llvm_ad_rgb``: vectorised through Dr.Jit's LLVM back-end; it needs a working system
  ``libLLVM`` (Debian: ``libllvm19``). With LLVM 15 the first render *aborts the process*
  (``LLVM ERROR: Cannot select ... fminimum`` on AVX-512), so :func:`variant_works` probes a variant
  in a child process before anybody renders with it.

Mitsuba's thread pool (nanothread, shared by both variants) is process-wide:
``threads=`` sets it through ``drjit.set_thread_count`` and it stays set for later renders.

Never write images with ``mi.util.write_bitmap(..., write_async=True)`` (its default) here: reading
the file back can hang. This module returns numpy arrays only.
"""
from __future__ import annotations

import functools
import os
import subprocess
import sys
import textwrap

import numpy as np


def import_mitsuba():
    """``import mitsuba`` or raise ImportError with the fix (the ``[ref]`` extra)."""
    try:
        import mitsuba as mi  # noqa: F401
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("Mitsuba 3 is not installed; install gdlearn's [ref] extra: "
                          "pip install -e '.[ref]'  (or: pip install mitsuba==3.9.1)") from err
    return mi


def _set_variant(variant: str):
    mi = import_mitsuba()
    if variant not in mi.variants():
        raise ValueError(f"Mitsuba variant {variant!r} is not compiled into this wheel; "
                         f"available: {', '.join(mi.variants())}")
    mi.set_variant(variant)
    return mi


def set_threads(threads: int | None) -> None:
    """Size Mitsuba's (process-wide) thread pool; ``None`` leaves it as it is."""
    if threads is not None:
        import drjit as dr
        dr.set_thread_count(int(threads))


@functools.lru_cache(maxsize=32)
def _load_cached(path: str, mtime: float, variant: str, defaults: tuple):
    mi = _set_variant(variant)
    # Mitsuba substitutes <default> parameters from strings, as on its command line (-D name=value).
    return mi.load_file(path, **{k: str(v) for k, v in defaults})


def load_mitsuba(path, variant: str = "scalar_rgb", **defaults):
    """``mi.load_file(path, **defaults)`` under ``variant``, cached per (file, mtime, variant,
    defaults) so repeated renders of one scene do not re-parse it."""
    path = os.path.abspath(os.fspath(path))
    _set_variant(variant)
    return _load_cached(path, os.path.getmtime(path), variant, tuple(sorted(defaults.items())))


def render_mitsuba(path, spp: int, seed: int, variant: str = "scalar_rgb", threads: int | None = None,
                   **defaults) -> np.ndarray:
    """Render the scene file ``path`` with Mitsuba 3 and return the image as H x W x 3 float64.

    ``spp`` samples per pixel, sampler ``seed`` (``mi.render(scene, seed=, spp=)``: different seeds
    give independent images), ``defaults`` override the file's ``<default>`` parameters, e.g.
    ``render_mitsuba("scenes/cornell-box.xml", 64, 0, res=32, max_depth=2)``. Call
    :func:`variant_works` first for any variant other than ``scalar_rgb``.
    """
    mi = _set_variant(variant)
    set_threads(threads)
    scene = load_mitsuba(path, variant, **defaults)
    img = np.array(mi.render(scene, seed=int(seed), spp=int(spp)), dtype=np.float64)
    return img[..., :3]


def mitsuba_mean_stderr(path, spp: int, seeds, variant: str = "scalar_rgb",
                        threads: int | None = None, **defaults) -> tuple[np.ndarray, np.ndarray]:
    """Mean image over the independent renders at ``seeds`` (``spp`` each) and its per-pixel standard
    error, the sample standard deviation over seeds divided by sqrt(K) (K = len(seeds) >= 2)."""
    seeds = list(seeds)
    if len(seeds) < 2:
        raise ValueError("mitsuba_mean_stderr needs at least 2 seeds to estimate a standard error")
    imgs = np.stack([render_mitsuba(path, spp, s, variant, threads, **defaults) for s in seeds])
    return imgs.mean(axis=0), imgs.std(axis=0, ddof=1) / np.sqrt(len(seeds))


_PROBE = textwrap.dedent("""
    import sys, numpy as np, mitsuba as mi
    mi.set_variant(sys.argv[1])
    scene = mi.load_dict(mi.cornell_box())
    img = np.array(mi.render(scene, spp=2, seed=0))
    assert np.isfinite(img).all() and img.mean() > 0, "probe image is empty or not finite"
    print("ok")
""")


@functools.lru_cache(maxsize=None)
def variant_works(variant: str, timeout: float = 300.0) -> tuple[bool, str]:
    """Does ``variant`` render here? Probed in a child process, because a broken LLVM back-end aborts
    the whole process instead of raising. Returns ``(ok, reason)``; ``reason`` says what failed and,
    for ``llvm_*`` variants, the fix."""
    try:
        mi = import_mitsuba()
    except ImportError as err:
        return False, str(err)
    if variant not in mi.variants():
        return False, f"variant {variant} is not in this Mitsuba wheel ({', '.join(mi.variants())})"
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE, variant], capture_output=True, text=True,
                           timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, f"variant {variant}: probe render did not finish in {timeout:.0f} s"
    if r.returncode == 0 and r.stdout.strip().endswith("ok"):
        return True, "ok"
    tail = (r.stderr.strip().splitlines() or ["(no output)"])[-1]
    fix = (" -- fix: install LLVM >= 16, e.g. Debian/Ubuntu: apt-get install -y libllvm19 "
           "(or point DRJIT_LIBLLVM_PATH at a libLLVM.so)") if variant.startswith("llvm") else ""
    return False, f"variant {variant} failed (exit {r.returncode}): {tail}{fix}"
