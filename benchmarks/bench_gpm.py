"""Gradient-domain photon mapping's costs and its equal-time standing: gpm vs sppm (vs pt).

Default: per scene, JIT warmed, the passes of sppm and gpm *interleaved* (sppm, gpm, sppm, ...;
both see the same load) and the median time of a pass of each, their ratio (Hua et al. 2017
report 1.5-3.5x), the stage split, and gpm's photon-shift statistics (reconnected / failed /
moved by the manifold walk, per gathered photon and shift).

    .venv/bin/python benchmarks/bench_gpm.py [--scenes scenes/cornell-box.xml,...] [--res 128]
        [--photons 100000] [--repeats 4]

``--equal-time S``: sppm, gpm (its MIS primal), gpm+l1, gpm+l2 and pt for S seconds each (JIT
excluded, reconstruction included) on every scene, ``--seeds`` seeds interleaved seed by seed,
against Mitsuba 3's image (``--ref-spp`` spp over 8 seeds, llvm_ad_rgb, cached); prints each
method's final relMSE per seed and the ratio sppm / method (> 1: lower error than SPPM), also with
the reference's noise floor subtracted from both errors. ``--photons`` defaults to the photon
integrators' own 100k light paths a pass. A path tracer's reference of a caustic is noisy: at 128²
the caustics box's floor was 3.5e-4 at 16384 spp, a third of gpm's error; issue 15's study took
262144 spp there (~20 min, once: the reference is cached) and 65536 on the other scenes.

    .venv/bin/python benchmarks/bench_gpm.py --equal-time 20 --res 128 --seeds 3 --ref-spp 65536

``--sweep SCALES``: the first kernel radius, ``radius_scale`` x the pixel footprint, for each scale
and each method of ``--methods`` (e.g. sppm,gpm+l1) at equal time (``--equal-time``, default 20 s)
over ``--seeds`` seeds: the final relMSE split by ``experiments.metrics.bias_variance`` into the
squared bias of the kernel's blur (the reference's floor included) and the variance of one run, and
the passes each run completed. This chose gpm's default ``radius_scale`` (gpm.RADIUS_SCALE).

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gpm.py --sweep 0.25,0.35,0.5,0.7,1,1.4 \
        --methods sppm,gpm+l1 --res 128 --seeds 3 --scenes scenes/cornell-box.xml

``--kernel``: the camera pass alone, the fast kernel (gpm_gather.gpm_rows) against the one it replaced
(tests/_gpm_reference.py, which records tests/golden/passes/) on the same photons and radii (pass 1 after
pass 0's radius reduction), interleaved (old, new, old, ...) in one process, ``--repeats`` times; prints
the median and the minimum of each, their ratio and the load average before and after.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gpm.py --kernel --res 64 --photons 50000 \
        --scenes scenes/cornell-box.xml,scenes/caustics-box.xml --repeats 5

``--fig4``: Hua et al. 2017's Fig. 4 -- only the photons whose parent vertex is specular
(``parent="specular"``: the manifold branch's subset; the emission the camera sees left out), at one
fixed radius (``--radius-scale`` x the mean pixel footprint, alpha = 1, so every pass estimates the
same blurred image), ``--passes`` passes of gpm per seed; at pass checkpoints the relMSE of the
primal and of the L1 and L2 reconstructions against a ``--ref-passes`` sppm run of the same subset
and radius (another seed), and their ratios per seed. Unbiased gradients keep the ratio flat as the
passes grow (every error is variance, falling as 1/passes); a ratio that sinks towards 1 is a bias
of the gradients showing through the falling variance.

    .venv/bin/python benchmarks/bench_gpm.py --fig4 --scenes scenes/mirror-caustic.xml,scenes/caustics-box.xml \
        --res 64 --photons 100000 --passes 32 --seeds 3
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.bench_gvpm import interleaved_times, old_vs_new  # noqa: E402
from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402

SCENES = "scenes/cornell-box.xml,scenes/caustics-box.xml,scenes/caustic-closeup.xml"


def pass_times(path, a) -> None:
    scene = load(path, res=a.res)
    integs = {n: make(n, scene, seed=0, photons_per_pass=a.photons, threads=a.threads) for n in ("sppm", "gpm")}
    med, last = interleaved_times(integs, a.repeats)     # the first pass also measures the initial radii
    st = last["gpm"].stats
    ok, fail, mani = st["photon_shifts_reconnected"], st["photon_shifts_failed"], st["photon_shifts_manifold"]
    tot = max(ok + fail + mani, 1)
    stage = {k: last["gpm"].timings.get(k, 0.0) for k in ("photons", "build", "gather")}
    print(f"{os.path.basename(path):22s} sppm {med['sppm']:6.3f} s/pass  gpm {med['gpm']:6.3f} s/pass  "
          f"gpm/sppm {med['gpm'] / med['sppm']:5.2f}  (gpm: light paths {stage['photons']:.3f} s, build "
          f"{stage['build']:.3f} s, gather {stage['gather']:.3f} s)  photon shifts: reconnected {ok / tot:.1%}, "
          f"failed {fail / tot:.1%}, manifold {mani / tot:.1%}", flush=True)


def kernel_times(path, a) -> None:
    """Old and new camera pass on the same photons and radii, interleaved (module docstring)."""
    import numpy as np

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
    import _gpm_reference as ref
    from gdlearn.integrators.photon import gpm_gather as gg

    load0 = os.getloadavg()[0]
    g = make("gpm", load(path, res=a.res), seed=0, photons_per_pass=a.photons, threads=a.threads)
    g.compile()
    g.render_pass(0)
    lp, grids = g.build(g.trace_photons(1))
    radius = np.sqrt(g.r2)
    kernels = {"old": ref.reference_rows, "new": gg.gpm_rows}

    def call(rows, out):
        with g.setup.parallel(g.height):
            rows(g.setup.sa, lp, grids, g.mtab, g.gather_params, g.seed, 2, radius, out)

    line, outs = old_vs_new(kernels, call, lambda: gg.allocate(g.height, g.width), a.repeats)
    c = outs["new"].count.sum(axis=(0, 2, 3))
    print(f"{os.path.basename(path):22s} {line}  shifts {int(c.sum())} (manifold {int(c[gg.MANIFOLD])})  load "
          f"average {load0:.2f} -> {os.getloadavg()[0]:.2f}", flush=True)


def mitsuba_scene(path, a):
    """(SceneFile at --res, Mitsuba 3's image of it: --ref-spp spp over 8 seeds, llvm_ad_rgb, cached)."""
    from gdlearn.experiments import SceneFile
    from gdlearn.experiments.references import mitsuba_reference

    sf = SceneFile(path, (("res", a.res),))
    ref = mitsuba_reference(sf, spp=a.ref_spp, seeds=range(101, 109), variant="llvm_ad_rgb")
    print(f"\n{sf.name}: reference Mitsuba {ref.spp} spp, relMSE floor {ref.floor:.2e}", flush=True)
    return sf, ref


def equal_time_study(a) -> int:
    import numpy as np

    from gdlearn.experiments import equal_time
    from gdlearn.experiments.study import Method

    opts = (("photons_per_pass", a.photons), ("threads", a.threads))
    every = {"sppm": Method("sppm", "sppm", None, opts), "gpm": Method("gpm", "gpm", None, opts),
             "gpm+l1": Method("gpm+l1", "gpm", "l1", opts), "gpm+l2": Method("gpm+l2", "gpm", "l2", opts), "pt": "pt"}
    names = a.methods.split(",")
    methods = [every[n] for n in names]
    print(f"equal time {a.equal_time:.1f} s per run, {a.res}x{a.res}, {a.seeds} seeds, {a.photons} light paths a "
          f"pass; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    for path in a.scenes.split(","):
        sf, ref = mitsuba_scene(path, a)
        err = {m: [] for m in names}
        for seed in range(a.seeds):
            st = equal_time(methods, [sf], seconds=a.equal_time, seeds=[seed], references=ref, executor="serial",
                            count=4)
            for m in names:
                err[m].append(st.select(True, method=m, seed=seed)[0]["relmse"])
        base = np.array(err["sppm"])
        for m in names:
            e = np.array(err[m])
            ratio = base / e
            clean = np.maximum(base - ref.floor, 0) / np.maximum(e - ref.floor, 1e-300)
            print(f"  {m:7s} relMSE {e.mean():.3e} (seeds: {', '.join(f'{x:.3e}' for x in e)})  sppm / {m}: mean "
                  f"{ratio.mean():.2f}, min {ratio.min():.2f}, max {ratio.max():.2f}; less the floor: mean "
                  f"{clean.mean():.2f}, min {clean.min():.2f}, max {clean.max():.2f}", flush=True)
        print(f"  load average {os.getloadavg()[0]:.2f}")
    return 0


def radius_sweep(a) -> int:
    """Bias and variance against the first kernel radius (module docstring, ``--sweep``)."""
    from gdlearn.experiments import bias_variance, equal_time
    from gdlearn.experiments.study import Method

    seconds = a.equal_time or 20.0
    scales = [float(x) for x in a.sweep.split(",")]
    names = a.methods.split(",")
    print(f"radius sweep: {seconds:.1f} s per run, {a.res}x{a.res}, {a.seeds} seeds, {a.photons} light paths a pass; "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    for path in a.scenes.split(","):
        sf, ref = mitsuba_scene(path, a)
        for name in names:
            est, _, solver = name.partition("+")
            for scale in scales:
                opts = (("photons_per_pass", a.photons), ("threads", a.threads), ("radius_scale", scale))
                m = Method(f"{name}@{scale:g}", est, solver or None, opts)
                st = equal_time([m], [sf], seconds=seconds, seeds=a.seeds, references=ref, executor="serial", count=2)
                bv = bias_variance(st.seed_images(m.label, sf.name), ref.image)
                passes = [r["passes"] for r in st.select(True, method=m.label)]
                print(f"  {name:7s} radius_scale {scale:5.2f}: relMSE {bv['relmse']:.3e} = bias^2 {bv['bias2']:.3e} "
                      f"+ variance {bv['variance']:.3e}; passes {', '.join(map(str, passes))}", flush=True)
        print(f"  load average {os.getloadavg()[0]:.2f}")
    return 0


def fig4_study(a) -> int:
    """Primal vs reconstructions on the specular-parent subset (module docstring)."""
    import numpy as np

    from gdlearn.experiments import SceneFile
    from gdlearn.experiments.metrics import relmse
    from gdlearn.experiments.progressive import pass_schedule, snapshot
    from gdlearn.experiments.references import render_reference
    from gdlearn.experiments.study import load_scene
    from gdlearn.kernels.pathclass import CLASS_NAMES

    effects = [c for c in CLASS_NAMES if c != "emission"]
    marks = pass_schedule(a.passes, 6)
    names = ("primal", "l1", "l2")
    print(f"Fig. 4 (specular-parent photons, fixed radius): {a.res}x{a.res}, {a.photons} light paths a pass, "
          f"{a.passes} passes x {a.seeds} seeds; load average {os.getloadavg()[0]:.2f}")
    for path in a.scenes.split(","):
        sf = SceneFile(path, (("res", a.res),))
        probe = make("sppm", load_scene(sf), seed=0, photons_per_pass=1000)
        probe.render_pass(0)
        opts = dict(parent="specular", radius=a.radius_scale * probe.pass_state()["mean_radius"], alpha=1.0,
                    photons_per_pass=a.photons, threads=a.threads)
        ref = render_reference(sf, "sppm", spp=2 * a.ref_passes, spp_per_pass=2, effects=effects, **opts)
        err = {(m, p): [] for m in names for p in marks}
        moved = failed = 0
        for seed in range(a.seeds):
            integ = make("gpm", load_scene(sf), seed=seed, effects=tuple(effects), **opts)
            integ.warmup()
            for p in range(1, a.passes + 1):
                frame = integ.step()
                if p not in marks:
                    continue
                for m in names:
                    img = frame.primal if m == "primal" else snapshot(frame, m).image
                    err[m, p].append(relmse(img, ref.image))
            moved += frame.stats["photon_shifts_manifold"]
            failed += frame.stats["photon_shifts_failed"]
        print(f"\n{sf.name}: radius {opts['radius']:.4f}, reference sppm {a.ref_passes} passes (relMSE floor "
              f"{ref.floor:.1e}); photon shifts of the last passes: manifold {moved / max(moved + failed, 1):.0%}, "
              f"failed {failed / max(moved + failed, 1):.0%}")
        for p in marks:
            e = {m: np.array(err[m, p]) for m in names}
            print(f"  pass {p:3d}  relMSE primal {e['primal'].mean():.2e} l1 {e['l1'].mean():.2e} l2 {e['l2'].mean():.2e}  "
                  + "  ".join(f"primal/{m} {(e['primal'] / e[m]).mean():.2f} [{(e['primal'] / e[m]).min():.2f}-"
                              f"{(e['primal'] / e[m]).max():.2f}]" for m in ("l1", "l2")), flush=True)
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=SCENES)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--photons", type=int, default=100_000, help="light paths per pass (the integrators' default)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=4)
    ap.add_argument("--equal-time", type=float, default=None, metavar="S")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--ref-spp", type=int, default=65536)
    ap.add_argument("--methods", default="sppm,gpm,gpm+l1,gpm+l2,pt", help="of --equal-time; sppm first (the ratios' base)")
    ap.add_argument("--kernel", action="store_true", help="old vs new camera pass alone (module docstring)")
    ap.add_argument("--fig4", action="store_true", help="Hua et al. 2017 Fig. 4 (module docstring)")
    ap.add_argument("--passes", type=int, default=32, help="of --fig4, per seed")
    ap.add_argument("--ref-passes", type=int, default=400, help="of --fig4's sppm reference")
    ap.add_argument("--radius-scale", type=float, default=1.0, help="of --fig4: x the mean pixel footprint")
    ap.add_argument("--sweep", default=None, metavar="SCALES", help="first radii in pixel footprints (module docstring)")
    a = ap.parse_args(argv)
    if a.sweep:
        return radius_sweep(a)
    if a.fig4:
        return fig4_study(a)
    if a.kernel:
        print(f"camera pass alone, {a.res}x{a.res}, {a.photons} light paths, {a.threads} threads, median of "
              f"{a.repeats}, old and new interleaved")
        for path in a.scenes.split(","):
            kernel_times(path, a)
        return 0
    if a.equal_time is not None:
        return equal_time_study(a)
    print(f"{a.res}x{a.res}, {a.photons} light paths a pass, {a.threads} threads, median of {a.repeats} passes after "
          f"the first, interleaved; load average {os.getloadavg()[0]:.2f}")
    for path in a.scenes.split(","):
        pass_times(path, a)
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
