"""SPPM's costs: light paths per second against pt's camera paths per second, the gather and build
time per pass, and the memory a light-path vertex and a photon take.

Every kernel is JIT-warmed first; each stage is the median over ``--repeats`` passes after
the first (which also sets the initial radii and first touches the records' memory). Light paths
(trace + compaction into vertex records, :mod:`gdlearn.photons.trace`) and pt's camera paths
(one sample per pixel per path) are both full paths through the same scene, so their rates
compare the two halves of the work directly.

    .venv/bin/python benchmarks/bench_sppm.py [--scene scenes/cornell-box.xml] [--res 64]
        [--photons 200000] [--threads 2] [--repeats 3]

``--equal-time S`` instead runs the equal-time study of the chapter "Photon density estimation" at
benchmark size: pt and sppm get S seconds each (JIT excluded) on every ``--scenes`` scene, for
``--seeds`` seeds, interleaved seed by seed (pt, sppm, pt, sppm, ...) so both see the same load;
every final image is measured against a path-traced reference of ``--ref-spp`` spp (cached under
$GDLEARN_CACHE/references, its relMSE floor printed). It prints per scene the final relMSE of each
run, the per-seed ratio pt / sppm (> 1: sppm has the lower error), their mean and spread, and the
ratio with the reference's floor subtracted from both errors.

    .venv/bin/python benchmarks/bench_sppm.py --equal-time 20 --res 128 --seeds 3
        [--scenes scenes/caustics-box.xml,scenes/caustic-closeup.xml,benchmarks/scenes/caustic-small-light.xml,
                  scenes/cornell-box.xml] [--photons 1000000] [--ref-spp 16384] [--direct nee]
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
    ap.add_argument("--equal-time", type=float, default=None, metavar="S",
                    help="run the equal-time study pt vs sppm with S seconds per run instead")
    ap.add_argument("--scenes", default="scenes/caustics-box.xml,scenes/caustic-closeup.xml,"
                    "benchmarks/scenes/caustic-small-light.xml,scenes/cornell-box.xml")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--direct", choices=("photons", "nee"), default="photons",
                    help="sppm's direct light: photons, or emitter sampling at the gather point")
    a = ap.parse_args(argv)
    if a.equal_time is not None:
        return equal_time_study(a)
    scene = load(a.scene, res=a.res)

    sppm = make("sppm", scene, seed=0, photons_per_pass=a.photons, threads=a.threads)
    c0 = time.perf_counter()
    sppm.warmup()
    print(f"sppm compile {time.perf_counter() - c0:.1f} s")
    # pass 0 also sets the initial radii (a footprint gather) and touches the light-path memory
    # for the first time (later passes reuse it): reported apart, the medians are over passes 1..
    keys = ("photons", "build", "gather", "update")
    stages = {k: [] for k in keys}
    prev = dict.fromkeys(keys, 0.0)
    for i in range(a.repeats + 1):
        f = sppm.step()
        if i == 0:
            first = sum(f.timings[k] for k in keys)
        for k in keys:
            if i > 0:
                stages[k].append(f.timings[k] - prev[k])
            prev[k] = f.timings[k]
    stages = {k: statistics.median(v) for k, v in stages.items()}
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

    print(f"scene {a.scene} at {a.res}x{a.res}, {a.threads} threads, median of {a.repeats} passes after "
          f"the first ({first:.3f} s: initial radii, first touch of the records' memory); "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"light paths/s        {n_paths / stages['photons']:12.0f}  ({verts / n_paths:.2f} vertices, "
          f"{photons / n_paths:.2f} photons per path)")
    print(f"pt camera paths/s    {pt_rate:12.0f}")
    print(f"build per pass       {stages['build']:12.4f} s")
    print(f"gather per pass      {stages['gather']:12.4f} s  ({2 * a.res * a.res} gather points)")
    print(f"bytes per vertex     {BYTES_PER_VERTEX:12d}  ({BYTES_PER_VERTEX * verts / max(photons, 1):.0f} per photon "
          f"incl. the non-photon vertices; + ~72 in the hash grid: position, cell, id, buckets)")
    return 0


def equal_time_study(a) -> int:
    """pt vs sppm at equal time (module docstring)."""
    import numpy as np

    from gdlearn.experiments import SceneFile, equal_time
    from gdlearn.experiments.references import render_reference
    from gdlearn.experiments.study import Method

    methods = ["pt", Method("sppm", "sppm", None, (("photons_per_pass", a.photons), ("threads", a.threads),
                                                   ("direct", a.direct)))]
    print(f"equal time {a.equal_time:.1f} s per run, {a.res}x{a.res}, {a.seeds} seeds, sppm {a.photons} "
          f"light paths a pass, direct light by {a.direct}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    for path in a.scenes.split(","):
        sf = SceneFile(path, (("res", a.res),))
        t0 = time.perf_counter()
        ref = render_reference(sf, "pt", spp=a.ref_spp, spp_per_pass=64)
        print(f"\n{sf.name}: reference pt {a.ref_spp} spp ({time.perf_counter() - t0:.0f} s, cached after), "
              f"relMSE floor {ref.floor:.2e}")
        err = {"pt": [], "sppm": []}
        spp = {"pt": [], "sppm": []}
        for seed in range(a.seeds):
            st = equal_time(methods, [sf], seconds=a.equal_time, seeds=[seed], references=ref,
                            executor="serial", count=4, spp_per_pass=4)
            for m in err:
                r = st.select(True, method=m, seed=seed)[0]
                err[m].append(r["relmse"])
                spp[m].append(r["spp"])
        ratio = np.array(err["pt"]) / np.array(err["sppm"])
        # E[measured relMSE] = true relMSE + the reference's floor (metrics.relmse_floor): the
        # floor-corrected ratio is what a noiseless reference would show
        fixed = (np.array(err["pt"]) - ref.floor) / np.maximum(np.array(err["sppm"]) - ref.floor, 1e-300)
        for m in err:
            print(f"  {m:5s} relMSE {np.mean(err[m]):.3e}  (seeds: {', '.join(f'{e:.3e}' for e in err[m])}; "
                  f"{np.mean(spp[m]):.0f} spp)")
        print(f"  pt / sppm: mean {ratio.mean():.2f}, min {ratio.min():.2f}, max {ratio.max():.2f}  "
              f"(seeds: {', '.join(f'{r:.2f}' for r in ratio)}); load average {os.getloadavg()[0]:.2f}")
        print(f"  floor-corrected pt / sppm: mean {fixed.mean():.2f}, min {fixed.min():.2f}, max {fixed.max():.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
