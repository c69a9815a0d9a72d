"""What a surface-only scene saves by compiling the media code out (issue 2, item 3).

The same Cornell box (no medium) is rendered by the path tracer's two kernel entry points:
``render_rows_path`` -- what the effects plan picks for a scene without media -- and
``render_rows_volpath`` -- the volumetric kernel, whose medium branches then exist but never fire.
Both are JIT-warmed first; each is timed over the same passes (median of repeats) and the images are
compared as a same-work check (they estimate the same image; with the same random numbers they
agree to noise). Prints samples/s for both and the ratio.

    .venv/bin/python benchmarks/bench_effects.py [--res 128] [--spp 16] [--threads 2] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from gdlearn.integrators import make  # noqa: E402
from gdlearn.integrators.path.pt import render_rows_path, render_rows_volpath  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402


def timed(pt, kernel, spp, repeats):
    pt.kernel = kernel
    t0 = time.perf_counter()
    pt.compile()
    compile_s = time.perf_counter() - t0
    times, cpu, img = [], [], None
    for r in range(repeats):
        out = np.zeros((pt.setup.height, pt.setup.width, 3))
        t0, c0 = time.perf_counter(), time.process_time()
        pt._run(r * spp, spp, out)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        img = out if img is None else img + out
    return statistics.median(times), statistics.median(cpu), compile_s, img / repeats


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/cornell-box.xml")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    scene = load(a.scene, res=a.res, max_depth=a.max_depth)
    pt = make("pt", scene, seed=1, threads=a.threads)
    print(f"{a.scene} {a.res}x{a.res}, {a.spp} spp x {a.repeats} repeats, max_depth {a.max_depth}, "
          f"{a.threads} threads; plan: media={pt.setup.plan.media} -> kernel {pt.kernel.__name__}")
    n = a.res * a.res * a.spp
    t_s, u_s, c_s, img_s = timed(pt, render_rows_path, a.spp, a.repeats)
    t_v, u_v, c_v, img_v = timed(pt, render_rows_volpath, a.spp, a.repeats)
    # CPU seconds (all threads) make the comparison robust on a shared machine: wall time there
    # depends on what else runs, CPU time on the work done.
    print(f"{'kernel':<32}{'M samples/s':>12}{'M samples/CPU-s':>16}{'median s':>10}{'warm-up s':>11}"
          f"{'image mean':>12}")
    for name, t, u, c, img in (("surface (media compiled out)", t_s, u_s, c_s, img_s),
                               ("volume (media code present)", t_v, u_v, c_v, img_v)):
        print(f"{name:<32}{n / t / 1e6:>12.3f}{n / u / 1e6:>16.3f}{t:>10.3f}{c:>11.2f}{img.mean():>12.5f}")
    print(f"speed-up from compiling media out: x{t_v / t_s:.3f} wall, x{u_v / u_s:.3f} CPU   "
          f"(same-work check: image means differ by {abs(img_s.mean() / img_v.mean() - 1) * 100:.2f}%)")


if __name__ == "__main__":
    main()
