"""gpt (shift mappings + Eq. 17 MIS) against pt and gpt-replay: cost per pass, shift success rates,
gradient error at equal samples, relMSE at equal time.

    .venv/bin/python benchmarks/bench_gpt.py                      # 48x48, 5 scenes, 6 s x 2 seeds
    .venv/bin/python benchmarks/bench_gpt.py --res 24 --seconds 1 --seeds 1 --repeat 3 --ref-spp 512   # smoke run
    .venv/bin/python benchmarks/bench_gpt.py --ratios --res 32 --repeat 9   # gpt/pt per sample, every scene
    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_gpt.py --res 32 --grad-spp 16 --seeds 24 \
        --et-seeds 3 --seconds 4 --repeat 5 --ref-spp 4096 --threads 1 --et-policies replay+reconnection \
        halfvector+replay+reconnection halfvector+reconnection halfvector+reconnection+manifold
                                                                  # the run quoted in gdlearn.integrators.path.gpt

Scenes: ``cornell-box``, ``caustics-box``, ``fog-box``, ``mesh`` and ``caustic-closeup`` (manifold
exploration's scene) by default. A scene that ``make("gpt", scene)`` refuses is reported with the
integrator's error and skipped.

1. **Time per pass.** pt, gpt-replay and gpt with every supported policy render passes of the same
   samples (same seed, scene, spp, threads), interleaved so all see the same machine load; medians
   of ``--repeat`` passes, JIT warmed first (compile seconds printed apart). Ratios to pt.
2. **Shift statistics** of the timed gpt passes (``Frame.stats`` counters ``shift_<action>_*``,
   :func:`gdlearn.experiments.gradients.shift_summary`): per action, runs per base path (over the
   four offsets and all vertices) and the fraction that succeeded. Every failed step falls back to a
   finite difference for that path: ``fail`` counts Kettunen et al.'s vertex-class mismatches
   (including offsets that left the scene); a mixed policy's failures are replays (or half-vector
   copies) whose backward shift would reconnect.
3. **Gradient error at equal samples** (the STAR's Fig. 5): :func:`gdlearn.experiments.gradients.
   gradient_errors` -- relMSE of gx, gy against the finite differences of the reference, relative
   to the brightness of the pixel pair, ``--grad-spp`` samples, mean +- standard error over
   ``--seeds`` seeds, and the ratio replay / method of the mean errors with its *paired* standard
   error (every method renders the same seeds; :func:`paired_ratio`). Baseline: finite differences
   of pt's image at the same spp.
4. **Equal time** (:func:`gdlearn.experiments.equal_time`), per scene: pt, gpt-replay and gpt with
   each of ``--et-policies`` that runs there (``default``: the integrator's default policy), the
   gradient methods reconstructed with each of ``--solvers``, ``--seconds`` per run (JIT excluded,
   final reconstruction included), ``--et-seeds`` seeds, against a ``--ref-spp`` path-traced
   reference with an independent seed (cached on disk). ``pt/method`` and ``replay/method`` (replay
   = gpt-replay with the same solver) > 1 mean the method has the lower error.

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
from gdlearn.experiments.gradients import gradient_errors, shift_summary, summarize  # noqa: E402
from gdlearn.experiments.references import render_reference  # noqa: E402
from gdlearn.experiments.study import Method  # noqa: E402
from gdlearn.integrators import make  # noqa: E402
from gdlearn.integrators.path.gpt import MANIFOLD_POLICY, SUPPORTED  # noqa: E402

ACTIONS = ("replay", "halfvector", "reconnection", "manifold", "fail")


def scene_policies(name, scene_file, policies):
    """The policies gpt accepts on this scene (e.g. no manifold exploration in media); the others are
    printed with the integrator's error. The manifold policy is skipped where its walk does not run
    (no specular chain: it is halfvector+reconnection there, the same numbers twice)."""
    scene, out = scene_file.load(), []
    for p in policies:
        try:
            integ = make("gpt", scene, seed=0, shift=p)
        except ValueError as e:
            print(f"{name}: policy {p} skipped: {e}")
            continue
        if p == MANIFOLD_POLICY and not integ.manifold:
            print(f"{name}: policy {p} skipped: no specular chain the walk could move "
                  "(it is halfvector+reconnection here)")
            continue
        out.append(p)
    return out


def integrators(scene, spp, threads, policies):
    out = {"pt": make("pt", scene, seed=0, spp_per_pass=spp, threads=threads),
           "gpt-replay": make("gpt-replay", scene, seed=0, spp_per_pass=spp, threads=threads)}
    for p in policies:
        out[f"gpt[{p}]"] = make("gpt", scene, seed=0, spp_per_pass=spp, threads=threads, shift=p)
    return out


def time_per_pass(scene_file, spp, repeat, threads, policies):
    integs = integrators(scene_file.load(), spp, threads, policies)
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


def shipped_scenes():
    return sorted(os.path.splitext(n)[0] for n in os.listdir(os.path.join(ROOT, "scenes")) if n.endswith(".xml"))


def print_ratios(a):
    """Issue 20's table: per shipped scene gpt (default policy) and gpt-replay against pt, CPU seconds
    per sample of passes rendered interleaved on one thread (medians of ``--repeat``), JIT apart."""
    print(f"\n## CPU time per sample, 1 thread, {a.res}x{a.res}, {a.spp} spp a pass, median of {a.repeat}")
    print(f"{'scene':18s} {'policy':34s} {'pt us':>8s} {'gpt/pt':>7s} {'replay/pt':>9s} {'load':>5s}")
    for name, sf in supported_scenes(a.scenes or shipped_scenes(), a.res).items():
        scene = sf.load()
        integs = {m: make(m, scene, seed=0, spp_per_pass=a.spp, threads=1) for m in ("pt", "gpt", "gpt-replay")}
        for integ in integs.values():
            integ.warmup()
        cpu = {m: [] for m in integs}
        for i in range(a.repeat):
            for m, integ in integs.items():
                c0 = time.process_time()
                integ.render_pass(i)
                cpu[m].append(time.process_time() - c0)
        med = {m: float(np.median(v)) for m, v in cpu.items()}
        n = a.res * a.res * a.spp
        print(f"{name:18s} {integs['gpt'].shift:34s} {1e6 * med['pt'] / n:8.2f} {med['gpt'] / med['pt']:6.2f}x "
              f"{med['gpt-replay'] / med['pt']:8.2f}x {os.getloadavg()[0]:5.2f}", flush=True)


def print_costs(files, a):
    print(f"\n## time per pass ({a.spp} spp, median of {a.repeat}); ratio = method / pt")
    all_stats = {}
    for name, sf in files.items():
        t, jit, stats = time_per_pass(sf, a.spp, a.repeat, a.threads, a.ok[name])
        all_stats[name] = stats
        row = "  ".join(f"{m} {t[m]:.3f}s ({t[m] / t['pt']:.2f}x)" for m in t)
        print(f"{name:15s} {row}")
        print(f"{'':15s} JIT s: " + ", ".join(f"{m} {jit[m]:.1f}" for m in jit))
    print("\n## shift statistics of the timed gpt passes: runs per base path / success rate")
    print(f"{'scene':15s} {'policy':32s} " + " ".join(f"{x:>18s}" for x in ACTIONS))
    for name, stats in all_stats.items():
        for p in a.ok[name]:
            s = shift_summary(stats[f"gpt[{p}]"])
            cells = []
            for x in ACTIONS:
                c = s.get(x)
                if c is None or c["per_path"] == 0:
                    cells.append(f"{'-':>18s}")
                else:
                    cells.append(f"{c['per_path']:8.3f} / {c['success']:7.1%}")
            print(f"{name:15s} {p:32s} " + " ".join(f"{c:>18s}" for c in cells))


def paired_ratio(recs, base, label, name):
    """error(base) / error(label), the ratio of the mean errors over seeds, with its standard error from
    the *paired* seeds (delta method with their covariance): every method renders the same seeds, and
    gpt's base paths are pt's and gpt-replay's for the same seed, so the two errors are correlated and
    the paired error separates methods far better than two independent means do."""
    err = {}
    for r in recs:
        if r["scene"] == name and r["method"] in (base, label):
            err.setdefault(r["seed"], {})[r["method"]] = r["grad_relmse"]
    pairs = np.array([(e[base], e[label]) for e in err.values() if base in e and label in e])
    y, x = pairs[:, 0], pairs[:, 1]
    q = y.mean() / x.mean()
    if len(pairs) < 2:
        return float(q), float("nan")
    c = np.cov(y, x)
    rel = c[0, 0] / y.mean() ** 2 + c[1, 1] / x.mean() ** 2 - 2 * c[0, 1] / (y.mean() * x.mean())
    return float(q), float(q * np.sqrt(max(rel, 0.0) / len(pairs)))


def print_gradient_error(files, refs, a):
    print(f"\n## gradient relMSE at equal samples ({a.grad_spp} spp, mean +- stderr of {a.seeds} seeds; "
          "ratio = replay / method, of the mean errors, +- its paired stderr)")
    for name, sf in files.items():
        methods = [Method("pt (finite differences)", "pt"), Method("replay (gpt-replay)", "gpt-replay")]
        methods += [Method(p, "gpt", None, (("shift", p),)) for p in a.ok[name]]
        recs = gradient_errors(methods, [sf], spp=a.grad_spp, seeds=range(100, 100 + a.seeds),
                               references=refs, spp_per_pass=max(1, a.grad_spp // 4))
        summ = summarize(recs)
        for m in methods:
            s = summ[(m.label, name)]
            q, se = paired_ratio(recs, "replay (gpt-replay)", m.label, name)
            print(f"{name:15s} {m.label:32s} {s['mean']:10.3e} +- {s['stderr']:8.1e}   {q:5.2f}x +- {se:4.2f}")


#: the sources a pt reference's image depends on (its cache key, references.source_digest): an edit
#: elsewhere in gdlearn (a shift, a photon estimator, the experiments module) keeps a long reference
#: valid, so runs before and after such an edit are judged against the same image
PT_SOURCES = ("kernels", "scene", "integrators/base.py", "integrators/path/pt.py", "integrators/path/surface.py",
              "integrators/path/volume.py", "integrators/path/packet.py", "integrators/path/params.py",
              "integrators/path/accumulate.py")


def pt_reference(sf, a):
    fx = {"effects": a.effects} if a.effects else {}
    return render_reference(sf, "pt", spp=a.ref_spp, spp_per_pass=64, sources=PT_SOURCES, **fx)


def references(files, a):
    refs = {}
    for name, sf in files.items():
        t0 = time.perf_counter()
        refs[name] = pt_reference(sf, a)
        print(f"reference {name}: {time.perf_counter() - t0:.1f} s (cached after the first run), "
              f"noise floor {refs[name].floor:.2e}")
    return refs


def print_equal_time(files, refs, a):
    print(f"\n## equal time: {a.seconds:.1f} s per run, {a.et_seeds} seeds, reference pt {a.ref_spp} spp"
          + (f", effects {a.effects}" if a.effects else ""))
    print(f"{'scene':15s} {'method':44s} {'spp':>6s} {'relMSE':>10s} {'min..max over seeds':>22s} "
          f"{'pt/method':>10s} {'replay/method':>14s} {'pt/method less floor':>21s}")
    fx = (("effects", a.effects),) if a.effects else ()       # the request of every run and the reference
    for name, sf in files.items():            # per scene: the policies gpt runs there (a.ok)
        methods = [Method("pt", "pt", None, fx)] + [Method(f"gpt-replay+{s}", "gpt-replay", s, fx) for s in a.solvers]
        for p in a.et_policies:
            if p == "default":
                methods += [Method(f"gpt[default: {make('gpt', sf.load()).shift}]+{s}", "gpt", s, fx)
                            for s in a.solvers]
            elif p in a.ok[name]:
                methods += [Method(f"gpt[{p}]+{s}", "gpt", s, (("shift", p),) + fx) for s in a.solvers]
        study = equal_time(methods, [sf], seconds=a.seconds, seeds=a.et_seeds, references=refs,
                           executor="serial", count=6, first=a.seconds / 10, spp_per_pass=2)
        vs_pt = study.equal_time_ratios("pt")
        vs_rep = {s: study.equal_time_ratios(f"gpt-replay+{s}") for s in a.solvers}
        own = study.equal_time_ratios("pt", less_floor=True)
        for m in methods:
            fin = study.select(True, method=m.label, scene=name)
            err = [r["relmse"] for r in fin]
            rep = (f"{vs_rep[m.solver][(m.label, name)]:13.2f}x" if m.estimator == "gpt" else f"{'':14s}")
            print(f"{name:15s} {m.label:44s} {np.mean([r['spp'] for r in fin]):6.0f} {np.mean(err):10.3e} "
                  f"{min(err):10.2e}..{max(err):9.2e} {vs_pt[(m.label, name)]:9.2f}x {rep} "
                  f"{own[(m.label, name)]:20.2f}x", flush=True)
        print(f"{name:15s} reference noise floor {refs[name].floor:.2e} (in every relMSE above; the last column "
              f"subtracts it from both)")


def supported_scenes(names, res):
    """SceneFiles of the scenes gpt accepts; the others are reported with the integrator's error."""
    files = {}
    for n in names:
        sf = SceneFile(os.path.join(ROOT, "scenes", f"{n}.xml"), (("res", res),))
        try:
            make("gpt", sf.load(), seed=0)
        except ValueError as e:
            print(f"skipped {n}: {e}")
            continue
        files[n] = sf
    return files


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["cornell-box", "caustics-box", "fog-box", "mesh",
                                                     "caustic-closeup"])
    ap.add_argument("--policies", nargs="+", default=list(SUPPORTED), choices=list(SUPPORTED))
    ap.add_argument("--et-policies", nargs="+", default=["default"], choices=["default"] + list(SUPPORTED),
                    help="gpt policies in the equal-time study, 'default' = gpt's default_policy per scene, "
                         "each where gpt runs it (each costs seeds x scenes x solvers runs)")
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=4, help="samples per pixel of one timed pass")
    ap.add_argument("--repeat", type=int, default=5, help="timed passes per integrator (median)")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--seconds", type=float, default=6.0, help="equal-time budget per run")
    ap.add_argument("--seeds", type=int, default=2, help="seeds of the equal-sample gradient study")
    ap.add_argument("--et-seeds", type=int, default=None, help="seeds of the equal-time study (default --seeds)")
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--grad-spp", type=int, default=16)
    ap.add_argument("--solvers", nargs="+", default=["l1", "l2"])
    ap.add_argument("--effects", default=None,
                    help="effects request of the equal-time study: every run and its reference (default: all)")
    ap.add_argument("--no-equal-time", action="store_true")
    ap.add_argument("--ratios", action="store_true",
                    help="only issue 20's table: CPU time per sample of gpt and gpt-replay over pt on every "
                         "shipped scene (or --scenes), one thread")
    a = ap.parse_args()
    a.et_seeds = a.et_seeds or a.seeds
    if a.ratios:
        a.scenes = a.scenes if "--scenes" in sys.argv else None
        print(f"# gpt vs pt time per sample: load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
        print_ratios(a)
        return
    print(f"# gpt vs pt / gpt-replay: {a.res}x{a.res}, load average {os.getloadavg()[0]:.2f} "
          f"on {os.cpu_count()} cores, threads {a.threads or 'all'}; policies {', '.join(a.policies)}")
    files = supported_scenes(a.scenes, a.res)
    a.ok = {name: scene_policies(name, sf, a.policies) for name, sf in files.items()}
    print_costs(files, a)
    refs = references(files, a)
    print_gradient_error(files, refs, a)
    if not a.no_equal_time:
        print_equal_time(files, refs, a)


if __name__ == "__main__":
    main()
