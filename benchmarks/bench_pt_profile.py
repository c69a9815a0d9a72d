#!/usr/bin/env python
"""Where the path tracer's time goes: samples/s of ``pt`` on 1 and 2 threads, and the cost of the
closest-hit traversal alone over the same camera rays.

    .venv/bin/python benchmarks/bench_pt_profile.py [--scene cornell-box] [--res 256] [--spp 8]

Every kernel is warmed (JIT compiled) before it is timed; each figure is the best of ``--repeat``
runs (the machine is shared, the best run is the least disturbed one).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numba  # noqa: E402
import numpy as np  # noqa: E402
from numba import njit, prange  # noqa: E402

from gdlearn.integrators import make  # noqa: E402
from gdlearn.integrators.pt import _rows_path  # noqa: E402
from gdlearn.kernels.bvh import STACK_SIZE, closest_hit  # noqa: E402
from gdlearn.kernels.camera import camera_ray  # noqa: E402
from gdlearn.scene.compile import borrowed  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402


@njit(cache=True, parallel=True, error_model="numpy")
def _camera_hits(sb, h, w, spp, out):
    """Closest hit of spp jittered camera rays per pixel (the traversal alone, no shading)."""
    for y in prange(h):
        stack = np.empty(STACK_SIZE, dtype=np.int32)
        n = 0
        for x in range(w):
            for s in range(spp):
                o, d, tmax = camera_ray(sb.camera, x + (s + 0.5) / spp, y + 0.5)
                t, prim, u, v = closest_hit(sb.nodes, sb.node_info, sb.prims, sb.prim_info, o, d, 0.0, tmax, stack)
                n += prim >= 0
        out[y] = n


def best(f, repeat):
    """(best wall seconds, CPU seconds of that run): on a shared machine the CPU time (all threads
    of this process) is the steadier measure of work done; wall time is what a user waits."""
    ts = []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        f()
        ts.append((time.perf_counter() - t0, time.process_time() - c0))
    return min(ts)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cornell-box")
    p.add_argument("--res", type=int, default=256)
    p.add_argument("--spp", type=int, default=8)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args(argv)
    scene = load(ROOT / "scenes" / f"{a.scene}.xml", res=a.res, max_depth=a.max_depth)
    print(f"numba threading layer: {numba.config.THREADING_LAYER} (active after first parallel call)")
    n = a.res * a.res * a.spp
    rows = []
    for threads in (1, 2):
        integ = make("pt", scene, seed=0, spp_per_pass=a.spp, threads=threads)
        integ.compile()
        dt, cpu = best(lambda: integ.render_pass(0), a.repeat)
        rows.append((f"pt, {threads} thread(s)", n / dt / 1e6, n / cpu / 1e6, "M samples/s"))
        if not integ.media:   # the same kernel on the owned (reference-counted) arrays, for comparison
            img, bad = np.zeros((a.res, a.res, 3)), np.zeros(a.res, dtype=np.int64)
            numba.set_num_threads(threads)
            dt, cpu = best(lambda: _rows_path(integ.sa, 0, 0, a.spp, integ.max_depth, integ.rr_depth, integ.mask,
                                              integ.threshold, img, bad), a.repeat)
            rows.append((f"pt, sa not borrowed, {threads} thread(s)", n / dt / 1e6, n / cpu / 1e6, "M samples/s"))
        sa = integ.sa
        out = np.zeros(a.res, dtype=np.int64)
        numba.set_num_threads(threads)
        for b in (False, True):
            _camera_hits(borrowed(sa) if b else sa, a.res, a.res, a.spp, out)
            dt, cpu = best(lambda: _camera_hits(borrowed(sa) if b else sa, a.res, a.res, a.spp, out), a.repeat)
            rows.append((f"closest_hit camera rays{' (borrowed sa)' if b else ''}, {threads} thread(s)",
                         n / dt / 1e6, n / cpu / 1e6, "M rays/s"))
    print(f"active threading layer: {numba.threading_layer()}")
    print(f"{'':50s} {'per wall s':>10s} {'per CPU s':>10s}")
    for name, v, c, unit in rows:
        print(f"{name:50s} {v:10.3f} {c:10.3f} {unit}")


if __name__ == "__main__":
    main()
