"""gpt (shift mappings + Eq. 17 MIS) against pt and gpt-replay: cost per pass, shift success rates,
relMSE at equal time.

    .venv/bin/python benchmarks/bench_gpt.py                      # 64x64, Cornell + caustics, 10 s x 2 seeds
    .venv/bin/python benchmarks/bench_gpt.py --res 32 --seconds 2 --seeds 1 --repeat 3   # smoke run

1. **Time per pass.** pt, gpt-replay and gpt with each shipped policy render passes of the same
   samples (same seed, scene, spp, threads), interleaved so all see the same machine load; medians
   of ``--repeat`` passes, JIT warmed first. Printed relative to pt.
2. **Shift statistics** of the timed gpt passes (``Frame.stats`` counters ``shift_<action>_*``):
   per action, how often it ran per base path and the fraction that succeeded; ``fail`` counts
   vertex-class mismatches (including offsets that left the scene).
3. **Gradient error at equal samples** (the STAR's Fig. 5 comparison): relMSE of gx, gy against
   the finite differences of the reference, ``--grad-spp`` samples, mean over ``--seeds`` seeds;
   replay is ``gpt-replay``; baseline: finite differences of pt's image at the same spp. relMSE = mean over pixels of (g - g_ref)^2 / (g_ref^2 + 1e-2).
4. **Equal time** (``gdlearn.experiments.equal_time``): pt, gpt-replay and gpt per policy, the
   gradient methods reconstructed with each ``--solvers``, ``--seconds`` per run (JIT excluded,
   final reconstruction included) on ``--seeds`` seeds, against a ``--ref-spp`` path-traced
   reference with an independent seed (cached on disk). ``pt/method`` > 1 means the method wins.

Nothing is asserted: numbers depend on the machine and its load (printed in the header).
"""
import argparse
import os
import time

import numpy as np

from gdlearn.experiments import SceneFile, equal_time
from gdlearn.experiments.references import render_reference
from gdlearn.experiments.study import Method
from gdlearn.integrators import make, render
from gdlearn.integrators.gpt import SUPPORTED

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
POLICIES = ("replay+reconnection", "halfvector+reconnection")
ACTIONS = ("replay", "halfvector", "reconnection", "fail")


def integrators(scene, spp, threads):
    out = {"pt": make("pt", scene, seed=0, spp_per_pass=spp, threads=threads),
           "gpt-replay": make("gpt-replay", scene, seed=0, spp_per_pass=spp, threads=threads)}
    for p in POLICIES:
        out[f"gpt[{p}]"] = make("gpt", scene, seed=0, spp_per_pass=spp, threads=threads, shift=p)
    return out


def time_per_pass(scene_file, spp, repeat, threads):
    integs = integrators(scene_file.load(), spp, threads)
    jit = {name: integ.warmup() for name, integ in integs.items()}
    times = {name: [] for name in integs}
    stats = {name: {} for name in integs}
    for i in range(repeat):                    # interleaved: all see the same load
        for name, integ in integs.items():
            t0 = time.perf_counter()
            res = integ.render_pass(i)
            times[name].append(time.perf_counter() - t0)
            for k, v in res.stats.items():
                stats[name][k] = stats[name].get(k, 0) + v
    return {k: float(np.median(v)) for k, v in times.items()}, jit, stats


def print_costs(files, a):
    print(f"\n## time per pass ({a.spp} spp, median of {a.repeat}); ratio = method / pt")
    all_stats = {}
    for name, sf in files.items():
        t, jit, stats = time_per_pass(sf, a.spp, a.repeat, a.threads)
        all_stats[name] = stats
        row = "  ".join(f"{m} {t[m]:.3f}s ({t[m] / t['pt']:.2f}x)" for m in t)
        print(f"{name:13s} {row}")
        print(f"{'':13s} JIT s: " + ", ".join(f"{m} {jit[m]:.1f}" for m in jit))
    print("\n## shift statistics of the timed gpt passes: runs per base path, success rate")
    print(f"{'scene':13s} {'policy':26s} " + " ".join(f"{x:>20s}" for x in ACTIONS))
    for name, stats in all_stats.items():
        for p in POLICIES:
            st = stats[f"gpt[{p}]"]
            cells = []
            for x in ACTIONS:
                run = st.get(f"shift_{x}_run", 0)
                ok = st.get(f"shift_{x}_ok", 0)
                rate = f"{ok / run:.3f}" if run else "-"
                cells.append(f"{run / max(st['paths'], 1):9.3f} / {rate:>8s}")
            print(f"{name:13s} {p:26s} " + " ".join(f"{c:>20s}" for c in cells))


def _finite_differences(img):
    gx, gy = np.zeros_like(img), np.zeros_like(img)
    gx[:, :-1] = img[:, 1:] - img[:, :-1]
    gy[:-1] = img[1:] - img[:-1]
    return gx, gy


def _grad_relmse(frame, ref):
    err = []
    for g, r in ((frame.gx[:, :-1], ref[:, 1:] - ref[:, :-1]), (frame.gy[:-1], ref[1:] - ref[:-1])):
        err.append(((g - r) ** 2 / (r ** 2 + 1e-2)).mean())
    return float(np.mean(err))


def print_gradient_error(files, refs, a):
    print(f"\n## gradient relMSE at equal samples ({a.grad_spp} spp, mean of {a.seeds} seeds)")
    for name, sf in files.items():
        scene = sf.load()
        runs = [("replay (gpt-replay)", "gpt-replay", {})] + [(p, "gpt", {"shift": p}) for p in POLICIES]
        cells = []
        # baseline: finite differences of a path-traced image of the same samples (no shift at all)
        e = []
        for s in range(a.seeds):
            f = render(make("pt", scene, seed=100 + s, spp_per_pass=a.grad_spp, threads=a.threads), spp=a.grad_spp)
            f.images["gx"], f.images["gy"] = _finite_differences(f.primal)
            e.append(_grad_relmse(f, refs[name].image))
        cells.append(f"pt finite differences {np.mean(e):.3e}")
        for label, est, opts in runs:
            e = [_grad_relmse(render(make(est, scene, seed=100 + s, spp_per_pass=a.grad_spp, threads=a.threads,
                                          **opts), spp=a.grad_spp), refs[name].image) for s in range(a.seeds)]
            cells.append(f"{label} {np.mean(e):.3e}")
        print(f"{name:13s} " + "  ".join(cells))


def references(files, a):
    refs = {}
    for name, sf in files.items():
        t0 = time.perf_counter()
        refs[name] = render_reference(sf, "pt", spp=a.ref_spp, spp_per_pass=64)
        print(f"reference {name}: {time.perf_counter() - t0:.1f} s (cached after the first run), "
              f"noise floor {refs[name].floor:.2e}")
    return refs


def print_equal_time(files, refs, a):
    print(f"\n## equal time: {a.seconds:.1f} s per run, {a.seeds} seeds, reference pt {a.ref_spp} spp")
    methods = [Method.parse("pt")] + [Method.parse(f"gpt-replay+{s}") for s in a.solvers]
    for p in POLICIES:
        methods += [Method(f"gpt[{p}]+{s}", "gpt", s, (("shift", p),)) for s in a.solvers]
    study = equal_time(methods, list(files.values()), seconds=a.seconds, seeds=a.seeds, references=refs,
                       executor="serial", count=6, first=a.seconds / 10, spp_per_pass=2)
    ratios = study.equal_time_ratios("pt")
    print(f"{'scene':13s} {'method':36s} {'spp':>6s} {'relMSE':>10s} {'min..max over seeds':>22s} {'pt/method':>10s}")
    for name in files:
        for m in methods:
            fin = study.select(True, method=m.label, scene=name)
            err = [r["relmse"] for r in fin]
            print(f"{name:13s} {m.label:36s} {np.mean([r['spp'] for r in fin]):6.0f} {np.mean(err):10.3e} "
                  f"{min(err):10.2e}..{max(err):9.2e} {ratios[(m.label, name)]:9.2f}x")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["cornell-box", "caustics-box"])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=4, help="samples per pixel of one timed pass")
    ap.add_argument("--repeat", type=int, default=5, help="timed passes per integrator (median)")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--seconds", type=float, default=10.0, help="equal-time budget per run")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--grad-spp", type=int, default=16)
    ap.add_argument("--solvers", nargs="+", default=["l1", "l2"])
    ap.add_argument("--equal-time-scenes", nargs="+", default=["cornell-box"])
    ap.add_argument("--no-equal-time", action="store_true")
    a = ap.parse_args()
    assert set(POLICIES) <= set(SUPPORTED)
    print(f"# gpt vs pt / gpt-replay: {a.res}x{a.res}, load average {os.getloadavg()[0]:.2f} "
          f"on {os.cpu_count()} cores, threads {a.threads or 'all'}")
    files = {n: SceneFile(os.path.join(ROOT, "scenes", f"{n}.xml"), (("res", a.res),)) for n in a.scenes}
    print_costs(files, a)
    refs = references(files, a)
    print_gradient_error(files, refs, a)
    if not a.no_equal_time:
        print_equal_time({n: files[n] for n in a.equal_time_scenes if n in files}, refs, a)


if __name__ == "__main__":
    main()
