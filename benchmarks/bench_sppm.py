"""SPPM's costs: light paths per second against pt's camera paths per second, the gather and build
time per pass, and the memory a light-path vertex and a photon take.

Every kernel is JIT-warmed first; each stage is the median over ``--repeats`` passes. Light paths
(trace + compaction into vertex records, :mod:`gdlearn.photons.trace`) and pt's camera paths
(one sample per pixel per path) are both full paths through the same scene, so their rates
compare the two halves of the work directly.

    .venv/bin/python benchmarks/bench_sppm.py [--scene scenes/cornell-box.xml] [--res 64]
        [--photons 200000] [--threads 2] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from gdlearn.integrators import make  # noqa: E402
from gdlearn.photons.records import BYTES_PER_VERTEX  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/cornell-box.xml")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--photons", type=int, default=200_000, help="light paths per pass")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    scene = load(a.scene, res=a.res)

    sppm = make("sppm", scene, seed=0, photons_per_pass=a.photons, threads=a.threads)
    c0 = time.perf_counter()
    sppm.warmup()
    print(f"sppm compile {time.perf_counter() - c0:.1f} s")
    stages = {k: [] for k in ("photons", "build", "gather", "update")}
    for _ in range(a.repeats):
        f = sppm.step()
    for k in stages:           # per-pass means (the timings are summed over the passes)
        stages[k] = f.timings[k] / f.passes
    st = f.stats
    n_paths = st["light_paths"] / f.passes
    verts = st["light_vertices"] / f.passes
    photons = st["photons_stored"] / f.passes

    pt = make("pt", scene, seed=0, spp_per_pass=4, threads=a.threads)
    pt.warmup()
    times = []
    for i in range(a.repeats):
        t0 = time.perf_counter()
        pt.render_pass(i)
        times.append(time.perf_counter() - t0)
    pt_rate = a.res * a.res * 4 / statistics.median(times)

    print(f"scene {a.scene} at {a.res}x{a.res}, {a.threads} threads, {a.repeats} passes")
    print(f"light paths/s        {n_paths / stages['photons']:12.0f}  ({verts / n_paths:.2f} vertices, "
          f"{photons / n_paths:.2f} photons per path)")
    print(f"pt camera paths/s    {pt_rate:12.0f}")
    print(f"build per pass       {stages['build']:12.4f} s")
    print(f"gather per pass      {stages['gather']:12.4f} s  ({2 * a.res * a.res} gather points)")
    print(f"bytes per vertex     {BYTES_PER_VERTEX:12d}  ({BYTES_PER_VERTEX * verts / max(photons, 1):.0f} per photon "
          f"incl. the non-photon vertices; + ~72 in the hash grid: position, cell, id, buckets)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
