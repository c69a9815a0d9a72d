"""The surface pass of G-VPM's full image (gvol_surface.surface_pass, shared by G-BRE) alone: per scene,
one gvpm (transport="all") pass to compile and set the radii, then ``--repeats`` surface passes on
the same photons, their median and min seconds. Runs against whatever gdlearn ``PYTHONPATH`` points
at, so two checkouts can be compared in interleaved processes:

    for i in 1 2 3; do for root in /work/main /work/wt-gvol-surf; do
        PYTHONPATH=$root flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gvol_surface.py
    done; done
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)        # this tree's gdlearn, also when run from a worktree (else the editable install's)

import gdlearn  # noqa: E402
from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402


def surface_times(path: str, res: int, photons: int, repeats: int, threads: int):
    g = make("gvpm", load(path, res=res), seed=1, photons_per_pass=photons, transport="all", threads=threads)
    g.render_pass(0)                                   # compiles, and reduces the radii once
    lp = g.trace_photons(1)
    _, sgrids, _, _ = g.build(lp)
    radius = np.sqrt(g.r2)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = g._surface(lp, sgrids, 2, radius)
        times.append(time.perf_counter() - t0)
    return times, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", default="scenes/fog-box.xml,scenes/volume-caustic.xml")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--photons", type=int, default=100000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    for path in a.scenes.split(","):
        times, out = surface_times(path, a.res, a.photons, a.repeats, a.threads)
        c = out.count.sum(axis=(0, 2, 3))
        print(f"{gdlearn.__file__.split('/gdlearn/')[0]} {path} median {statistics.median(times):.3f} s "
              f"min {min(times):.3f} s  gathered {int(out.m.sum())} shifts {c.astype(int).tolist()}", flush=True)


if __name__ == "__main__":
    main()
