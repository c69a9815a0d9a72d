#!/usr/bin/env python
"""Samples per second: gdlearn's path tracer against Mitsuba 3 (scalar_rgb, llvm_ad_rgb), side by side.

    .venv/bin/python benchmarks/bench_pt_vs_mitsuba.py                    # 256^2, 64 spp, depth 8, 2 threads
    .venv/bin/python benchmarks/bench_pt_vs_mitsuba.py --spp 16 --repeat 1 --no-cold   # quick look

Same scene file, resolution, spp, max_depth and thread count for every renderer, all in one run.
Every renderer is warmed first (gdlearn: numba JIT via the integrator's ``compile``; Mitsuba: one
render of the same size, which for ``llvm_ad_rgb`` compiles its kernels), then the renderers are
timed ``--repeat`` times *round-robin* (so load from other processes hits them alike); the table
shows the median wall time, and the samples per CPU second of the process. The issue's goal is
gdlearn >= 1.0x ``llvm_ad_rgb``.

gdlearn's cold start is measured separately, in fresh processes: once with an empty numba cache
(``NUMBA_CACHE_DIR`` pointed at a new temporary folder: every kernel compiles) and once with the
on-disk cache that the first run filled (what a user sees the second time).

``llvm_ad_rgb`` is probed in a child process first (a broken libLLVM aborts the process) and left
out with the reason if it does not work (Debian/Ubuntu fix: ``apt-get install -y libllvm19``).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from gdlearn.crosscheck.mitsuba import import_mitsuba, load_mitsuba, set_threads, variant_works  # noqa: E402


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="*", default=["cornell-box", "fog-box"], help="scenes/<name>.xml")
    p.add_argument("--res", type=int, default=256)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeat", type=int, default=3, help="timed renders per renderer (median shown)")
    p.add_argument("--no-cold", action="store_true", help="skip the fresh-process cold-start runs")
    return p.parse_args(argv)


def gdlearn_runner(path, a):
    """(warm-up seconds, run(r) -> (wall s, CPU s, image mean)) for gdlearn's pt."""
    from gdlearn.integrators import make
    from gdlearn.scene.load import load

    scene = load(path, res=a.res, max_depth=a.max_depth)
    warm = make("pt", scene, seed=0, spp_per_pass=a.spp, threads=a.threads).warmup()   # JIT, cached

    def run(r):
        integ = make("pt", scene, seed=r, spp_per_pass=a.spp, threads=a.threads)
        integ.warmup()                                   # loads the compiled kernels: not timed
        c0 = time.process_time()
        frame = integ.step()                             # one pass of a.spp samples per pixel
        return frame.elapsed, time.process_time() - c0, float(np.mean(frame.primal))
    return warm, run


def mitsuba_runner(path, a, variant):
    """(first render seconds, run(r) -> (wall s, CPU s, image mean)) for a Mitsuba variant."""
    mi = import_mitsuba()
    mi.set_variant(variant)
    set_threads(a.threads)
    scene = load_mitsuba(path, variant, res=a.res, max_depth=a.max_depth)
    t0 = time.perf_counter()
    np.array(mi.render(scene, seed=0, spp=a.spp))       # warm-up: llvm compiles its kernels here
    first = time.perf_counter() - t0

    def run(r):
        mi.set_variant(variant)
        set_threads(a.threads)
        t0, c0 = time.perf_counter(), time.process_time()
        img = np.array(mi.render(scene, seed=r + 1, spp=a.spp))   # np.array forces evaluation
        return time.perf_counter() - t0, time.process_time() - c0, float(np.mean(img[..., :3]))
    return first, run


def time_round_robin(runners, repeat) -> dict:
    """Time every renderer ``repeat`` times, round-robin (a burst of load from other processes then
    hits every renderer alike): median wall and CPU seconds, and the last image mean."""
    runs = {who: [] for who in runners}
    for r in range(repeat):
        for who, (_, run) in runners.items():
            runs[who].append(run(r))
    out = {}
    for who, res in runs.items():
        out[who] = dict(seconds=statistics.median(x[0] for x in res), cpu=statistics.median(x[1] for x in res),
                        mean=res[-1][2], warm=runners[who][0])
    return out


_COLD = r"""
import json, sys, time
t0 = time.perf_counter()
from gdlearn.integrators import make, render
from gdlearn.scene.load import load
t1 = time.perf_counter()
scene = load(sys.argv[1], res=int(sys.argv[2]), max_depth=int(sys.argv[3]))
integ = make("pt", scene, seed=0, spp_per_pass=1, threads=int(sys.argv[4]))
t2 = time.perf_counter()
frame = render(integ, spp=1)
t3 = time.perf_counter()
print(json.dumps(dict(imports=t1 - t0, load=t2 - t1, compile=frame.timings.get("compile", 0.0),
                      first_pass=frame.elapsed, total=t3 - t0)))
"""


def cold_start(path, a, cache_dir=None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = cache_dir
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _COLD, str(path), str(a.res), str(a.max_depth),
                        str(a.threads)], capture_output=True, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - t0
    if r.returncode:
        raise RuntimeError(f"cold-start run failed:\n{r.stderr[-2000:]}")
    return dict(json.loads(r.stdout.strip().splitlines()[-1]), process=wall)


def main(argv=None) -> int:
    a = parse_args(argv)
    mi = import_mitsuba()
    variants = ["scalar_rgb"]
    ok, why = variant_works("llvm_ad_rgb")
    variants += ["llvm_ad_rgb"] if ok else []
    n = a.res * a.res * a.spp
    print(f"# gdlearn PT vs Mitsuba {mi.__version__}: {a.res}x{a.res}, {a.spp} spp, max_depth "
          f"{a.max_depth}, {a.threads} threads, median of {a.repeat}; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if not ok:
        print(f"# llvm_ad_rgb left out: {why}")
    rows = []
    for name in a.scenes:
        path = ROOT / "scenes" / f"{name}.xml"
        runners = {"gdlearn pt": gdlearn_runner(path, a)}
        for v in variants:
            runners[f"mitsuba {v}"] = mitsuba_runner(path, a, v)
        res = time_round_robin(runners, a.repeat)
        g = res["gdlearn pt"]
        for who, r in res.items():
            print(f"# {name}: {who} {r['seconds']:.2f} s", file=sys.stderr, flush=True)
            rows.append((name, who, r["seconds"], n / r["seconds"] / 1e6, n / r["cpu"] / 1e6,
                         g["mean"] / r["mean"], r["seconds"] / g["seconds"], r["warm"]))
    print(f"\n{'scene':12s} {'renderer':22s} {'seconds':>8s} {'Msamples/s':>11s} {'per CPU s':>10s} "
          f"{'gdlearn speed-up':>17s} {'mean ratio':>11s} {'warm-up s':>10s}")
    for scene, who, sec, msps, mcpu, mean_ratio, speedup, warm in rows:
        print(f"{scene:12s} {who:22s} {sec:8.2f} {msps:11.2f} {mcpu:10.2f} {speedup:16.2f}x "
              f"{mean_ratio:11.4f} {warm:10.2f}")
    print("\n# gdlearn speed-up = (this renderer's seconds) / (gdlearn's seconds): > 1 means gdlearn"
          " is faster.\n# per CPU s = samples per second of CPU time of all the process's threads (the"
          " work, whatever the load).\n# mean ratio = gdlearn image mean / this image mean (same work:"
          " ~1 up to noise).\n# warm-up s: gdlearn = JIT (numba cache) time; Mitsuba = first render"
          " incl. kernel compilation.")
    print(f"# load average after the run: {os.getloadavg()[0]:.2f}")
    if not a.no_cold:
        path = ROOT / "scenes" / f"{a.scenes[0]}.xml"
        with tempfile.TemporaryDirectory(prefix="gdlearn-numba-cold-") as d:
            cold = cold_start(path, a, d)
            warm = cold_start(path, a, d)
        print(f"\n# gdlearn cold start, fresh process, {a.scenes[0]}, 1 spp (seconds)")
        print(f"{'numba cache':14s} {'imports':>8s} {'load':>8s} {'JIT':>8s} {'1st pass':>9s} {'process':>8s}")
        for label, c in (("empty", cold), ("filled", warm)):
            print(f"{label:14s} {c['imports']:8.2f} {c['load']:8.2f} {c['compile']:8.2f} "
                  f"{c['first_pass']:9.3f} {c['process']:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
