#!/usr/bin/env python
"""Where the path tracer's time goes: samples/s of ``pt`` on 1 and 2 threads, and the cost of the
closest-hit traversal alone over the same camera rays.

    .venv/bin/python benchmarks/bench_pt_profile.py [--scene cornell-box] [--res 256] [--spp 8]

Every kernel is warmed (JIT compiled) before it is timed; the cases are then timed round-robin
``--repeat`` times and each figure is the best run (the machine is shared: the best run is the least
disturbed one). "per CPU s" divides by the CPU time of all this process's threads: on a loaded
machine it shows the work done, "per wall s" what a user waits.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numba  # noqa: E402
import numpy as np  # noqa: E402
from numba import njit, prange  # noqa: E402

from gdlearn.integrators import make  # noqa: E402
from gdlearn.kernels.accel.bvh import STACK_SIZE, closest_hit  # noqa: E402
from gdlearn.kernels.camera import camera_ray  # noqa: E402
from gdlearn.kernels.arrays import borrowed  # noqa: E402
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


def _with_threads(threads, f):
    def run():
        numba.set_num_threads(threads)
        f()
    return run


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cornell-box")
    p.add_argument("--res", type=int, default=256)
    p.add_argument("--spp", type=int, default=8)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args(argv)
    scene = load(ROOT / "scenes" / f"{a.scene}.xml", res=a.res, max_depth=a.max_depth)
    n = a.res * a.res * a.spp
    cases = []        # (label, unit, callable): all warmed first, then timed round-robin
    for threads in (1, 2):
        integ = make("pt", scene, seed=0, spp_per_pass=a.spp, threads=threads)
        integ.compile()
        cases.append((f"pt, {threads} thread(s)", "M samples/s", lambda integ=integ: integ.render_pass(0)))
        sa, out = integ.setup.sa, np.zeros(a.res, dtype=np.int64)
        for b in (False, True):
            f = (lambda sb=(borrowed(sa) if b else sa): _camera_hits(sb, a.res, a.res, a.spp, out))
            cases.append((f"closest_hit camera rays{' (borrowed sa)' if b else ''}, {threads} thread(s)",
                          "M rays/s", _with_threads(threads, f)))
    for _, _, f in cases:
        f()                                        # warm: JIT compile, caches, thread pool
    # round-robin repeats: a burst of load from other processes then hits every case alike; the best
    # wall time and the best CPU time (all threads of this process) of each case are kept
    wall = [float("inf")] * len(cases)
    cpu = [float("inf")] * len(cases)
    for _ in range(a.repeat):
        for k, (_, _, f) in enumerate(cases):
            t0, c0 = time.perf_counter(), time.process_time()
            f()
            wall[k] = min(wall[k], time.perf_counter() - t0)
            cpu[k] = min(cpu[k], time.process_time() - c0)
    print(f"# {a.scene} {a.res}x{a.res}, {a.spp} spp, max_depth {a.max_depth}; numba threading layer "
          f"{numba.threading_layer()}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"{'':50s} {'per wall s':>10s} {'per CPU s':>10s}")
    for (name, unit, _), w, c in zip(cases, wall, cpu):
        print(f"{name:50s} {n / w / 1e6:10.3f} {n / c / 1e6:10.3f} {unit}")


if __name__ == "__main__":
    main()
