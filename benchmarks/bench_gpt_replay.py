"""gpt-replay against the path tracer: cost per pass, and relMSE at equal time.

    .venv/bin/python benchmarks/bench_gpt_replay.py                       # 64x64, 10 s x 2 seeds per method
    .venv/bin/python benchmarks/bench_gpt_replay.py --res 32 --seconds 2 --seeds 1 --repeat 3   # smoke run

1. **Time per pass.** ``pt`` and ``gpt-replay`` passes of the same samples (same seed, scene, spp,
   threads), interleaved so that both see the same machine load; medians of ``--repeat`` passes,
   JIT warmed first. A gpt-replay pass traces the base paths (bit-identical to pt's: the "primal
   equal" column checks it) plus up to four offset paths each -- the STAR expects about 5x.
2. **Equal time.** ``gdlearn.experiments.equal_time`` runs pt and gpt-replay with each solver
   (cv, cv-weighted, l2, l1) for ``--seconds`` per run (JIT excluded, final reconstruction
   included) on ``--seeds`` seeds, against a ``--ref-spp`` path-traced reference with an
   independent seed (cached on disk; the book chapter uses the same cache key at 64x64). The ratio
   is mean final relMSE of pt / that of the method: > 1 means gpt-replay wins (the STAR reports
   "up to 2x" for this proof of concept).

Nothing is asserted: numbers depend on the machine and its load (printed in the header).
"""
import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)        # this tree's gdlearn, also when run from a worktree (else the editable install's)

import numpy as np  # noqa: E402

from gdlearn.experiments import SceneFile, equal_time  # noqa: E402
from gdlearn.experiments.references import render_reference  # noqa: E402
from gdlearn.integrators import make  # noqa: E402

SOLVERS = ("cv", "cv-weighted", "l2", "l1")


def time_per_pass(scene_file, spp, repeat, threads):
    scene = scene_file.load()
    pt = make("pt", scene, seed=0, spp_per_pass=spp, threads=threads)
    gpt = make("gpt-replay", scene, seed=0, spp_per_pass=spp, threads=threads)
    compile_s = {"pt": pt.warmup(), "gpt-replay": gpt.warmup()}
    times = {"pt": [], "gpt-replay": []}
    same = True
    stats = {}
    primal = None
    for i in range(repeat):                    # interleaved: both see the same load
        for name, integ in (("pt", pt), ("gpt-replay", gpt)):
            t0 = time.perf_counter()
            res = integ.render_pass(i)
            times[name].append(time.perf_counter() - t0)
            if name == "gpt-replay":
                stats = res.stats
                same &= bool(np.array_equal(res.images["primal"], primal))
            else:
                primal = res.images["primal"]
    return {k: float(np.median(v)) for k, v in times.items()}, compile_s, same, stats


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["cornell-box", "fog-box"])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=4, help="samples per pixel of one timed pass")
    ap.add_argument("--repeat", type=int, default=7, help="timed passes per integrator (median)")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--seconds", type=float, default=10.0, help="equal-time budget per run")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--no-equal-time", action="store_true")
    a = ap.parse_args()
    print(f"# gpt-replay vs pt: {a.res}x{a.res}, load average {os.getloadavg()[0]:.2f} "
          f"on {os.cpu_count()} cores, threads {a.threads or 'all'}")
    files = {n: SceneFile(os.path.join(ROOT, "scenes", f"{n}.xml"), (("res", a.res),)) for n in a.scenes}

    print(f"\n## time per pass ({a.spp} spp, median of {a.repeat})")
    print(f"{'scene':12s} {'pt s':>8s} {'gpt-replay s':>13s} {'ratio':>7s} {'shifts/path':>12s} "
          f"{'primal equal':>13s} {'JIT pt / gpt s':>15s}")
    for name, sf in files.items():
        t, c, same, stats = time_per_pass(sf, a.spp, a.repeat, a.threads)
        per_path = stats["shifts_traced"] / max(stats["paths"], 1)
        print(f"{name:12s} {t['pt']:8.3f} {t['gpt-replay']:13.3f} {t['gpt-replay'] / t['pt']:6.2f}x "
              f"{per_path:12.2f} {str(same):>13s} {c['pt']:7.1f} / {c['gpt-replay']:.1f}")
    if a.no_equal_time:
        return

    print(f"\n## equal time: {a.seconds:.1f} s per run, {a.seeds} seeds, reference pt {a.ref_spp} spp")
    refs = {}
    for name, sf in files.items():
        t0 = time.perf_counter()
        refs[name] = render_reference(sf, "pt", spp=a.ref_spp, spp_per_pass=64)
        print(f"reference {name}: {time.perf_counter() - t0:.1f} s (cached after the first run), "
              f"noise floor {refs[name].floor:.2e}")
    methods = ["pt"] + [f"gpt-replay+{s}" for s in SOLVERS]
    study = equal_time(methods, list(files.values()), seconds=a.seconds, seeds=a.seeds, references=refs,
                       executor="serial", count=6, first=a.seconds / 10, spp_per_pass=2)
    ratios = study.equal_time_ratios("pt")
    print(f"{'scene':12s} {'method':24s} {'spp':>6s} {'relMSE':>10s} {'min..max over seeds':>22s} "
          f"{'pt/method':>10s}")
    for name in files:
        for m in methods:
            fin = study.select(True, method=m, scene=name)
            err = [r["relmse"] for r in fin]
            print(f"{name:12s} {m:24s} {np.mean([r['spp'] for r in fin]):6.0f} {np.mean(err):10.3e} "
                  f"{min(err):10.2e}..{max(err):9.2e} {ratios[(m, name)]:9.2f}x")


if __name__ == "__main__":
    main()
