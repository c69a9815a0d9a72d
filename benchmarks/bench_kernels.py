"""Throughput of the material / phase / medium kernels, side by side with Mitsuba 3.

    .venv/bin/python benchmarks/bench_kernels.py [--n 1000000] [--no-mitsuba]

gdlearn: one numba loop per routine (JIT warmed first, one thread) -> ns per call, best of 3 in
process CPU time.
Mitsuba 3: the same BSDF's ``sample`` / ``eval`` on wide arrays in ``llvm_ad_rgb`` (vectorised, all
threads) and, for scale, ``scalar_rgb`` from Python on a small subset (dominated by call overhead).
The numbers are per-call costs, not an equal-hardware comparison: the path tracer's speed is what
matters and benchmarks/ has that; this script shows which BSDF is expensive.
"""
import argparse
import os
import sys
import time

import numpy as np
from numba import njit

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)        # this tree's gdlearn, also when run from a worktree (else the editable install's)

from gdlearn.kernels.bsdf import dispatch as B  # noqa: E402
from gdlearn.kernels.media import medium as M  # noqa: E402
from gdlearn.kernels.media import phase as P  # noqa: E402
from gdlearn.scene.model import BSDF, rgb  # noqa: E402

CASES = [
    ("diffuse", {"type": "diffuse"}, dict(type="diffuse")),
    ("roughconductor ggx", {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3},
     dict(type="roughconductor", distribution="ggx", alpha=0.3, reflectance=rgb(1.0))),
    ("roughconductor beckmann", {"type": "roughconductor", "alpha": 0.3},
     dict(type="roughconductor", alpha=0.3, reflectance=rgb(1.0))),
    ("dielectric", {"type": "dielectric"}, dict(type="dielectric")),
    ("roughdielectric ggx", {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3},
     dict(type="roughdielectric", distribution="ggx", alpha=0.3)),
    ("plastic", {"type": "plastic"}, dict(type="plastic", int_ior=1.49)),
    ("roughplastic ggx", {"type": "roughplastic", "distribution": "ggx"},
     dict(type="roughplastic", distribution="ggx", int_ior=1.49)),
]


@njit(cache=True)
def _bench_sample(row, wis, u):
    acc = 0.0
    for i in range(u.shape[0]):
        wo, w, pdf, d = B.bsdf_sample(row, (wis[i, 0], wis[i, 1], wis[i, 2]), u[i, 0], u[i, 1], u[i, 2])
        acc += w[0] + pdf
    return acc


@njit(cache=True)
def _bench_eval_pdf(row, wis, wos):
    acc = 0.0
    for i in range(wis.shape[0]):
        wi = (wis[i, 0], wis[i, 1], wis[i, 2])
        wo = (wos[i, 0], wos[i, 1], wos[i, 2])
        f = B.bsdf_eval(row, wi, wo)
        acc += f[0] + B.bsdf_pdf(row, wi, wo)
    return acc


@njit(cache=True)
def _bench_hg(g, wis, u):
    acc = 0.0
    for i in range(u.shape[0]):
        wo, pdf = P.hg_sample(g, (wis[i, 0], wis[i, 1], wis[i, 2]), u[i, 0], u[i, 1])
        acc += wo[0] + pdf
    return acc


@njit(cache=True)
def _bench_distance(u):
    acc = 0.0
    for i in range(u.shape[0]):
        t, sc, w = M.sample_distance((0.5, 1.0, 2.0), (0.8, 0.8, 0.8), 3.0, u[i, 0], u[i, 1])
        acc += t + w[0]
    return acc


def _timed(f, *args, reps=3):
    """Best-of-``reps`` process CPU time (robust when other jobs share the cores)."""
    f(*(a[:16] if isinstance(a, np.ndarray) else a for a in args))      # warm the JIT
    best = float("inf")
    for _ in range(reps):
        t = time.process_time()
        f(*args)
        best = min(best, time.process_time() - t)
    return best


def _mitsuba_llvm(md, wis, u):
    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    b = mi.load_dict(md)
    n = len(wis)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wis[:, 0], wis[:, 1], wis[:, 2])
    ctx = mi.BSDFContext()
    s1, s2 = mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2])
    out = []
    for rep in range(2):                        # first run compiles the kernel
        t = time.perf_counter()
        bs, w = b.sample(ctx, si, s1, s2)
        dr.eval(bs.wo, bs.pdf, w)
        dr.sync_thread()
        out.append(time.perf_counter() - t)
    return out[-1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--no-mitsuba", action="store_true")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    wis = rng.normal(size=(a.n, 3))
    wis /= np.linalg.norm(wis, axis=1)[:, None]
    wis[:, 2] = np.abs(wis[:, 2])
    wos = rng.normal(size=(a.n, 3))
    wos /= np.linalg.norm(wos, axis=1)[:, None]
    u = rng.random((a.n, 3))
    print(f"{'routine':28s}{'gdlearn sample':>16s}{'eval+pdf':>12s}{'mitsuba llvm sample':>22s}{'ratio':>8s}")
    for name, md, kw in CASES:
        row = B.material_row(BSDF(**kw), width=B.ROUGHPLASTIC_WIDTH)
        ts = _timed(_bench_sample, row, wis, u) / a.n * 1e9
        te = _timed(_bench_eval_pdf, row, wis, wos) / a.n * 1e9
        mi_s = ""
        ratio = ""
        if not a.no_mitsuba:
            try:
                tm = _mitsuba_llvm(md, wis, u) / a.n * 1e9
                mi_s = f"{tm:.1f} ns"
                ratio = f"{tm / ts:.2f}x"
            except Exception as err:                    # llvm variant unavailable: say so
                mi_s = f"n/a ({type(err).__name__})"
        print(f"{name:28s}{ts:13.1f} ns{te:9.1f} ns{mi_s:>22s}{ratio:>8s}")
    th = _timed(_bench_hg, 0.7, wis, u) / a.n * 1e9
    td = _timed(_bench_distance, u) / a.n * 1e9
    print(f"{'hg_sample (g=0.7)':28s}{th:13.1f} ns")
    print(f"{'sample_distance (RGB MIS)':28s}{td:13.1f} ns")
    t = time.perf_counter()
    B.material_row(BSDF(type="roughplastic", alpha=0.2), width=B.ROUGHPLASTIC_WIDTH)
    print(f"roughplastic table precomputation (beckmann): {time.perf_counter() - t:.2f} s")
    print("ratio = Mitsuba llvm time / gdlearn time per sample (>1: gdlearn faster; llvm uses all "
          "threads, gdlearn one)")


if __name__ == "__main__":
    main()
