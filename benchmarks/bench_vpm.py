"""The volumetric photon estimators' costs and their equal-time standing: vpm, bre (2D, 3D), pt.

Per estimator, JIT warmed, the median over ``--repeats`` passes after the first of each stage of a
pass (light paths traced, structures built -- hash grids for VPM, the bounding-box hierarchy for
the BRE, with the radii --, the camera gather), and the radius pre-pass of the variable kernels.

    .venv/bin/python benchmarks/bench_vpm.py [--scene scenes/fog-box.xml] [--res 64] [--photons 200000]
        [--threads 2] [--repeats 3]

``--equal-time S`` runs pt, vpm (progressive radii), vpm-knn (Jarosz's k-NN radius), bre-3d and bre-2d for S seconds each (JIT excluded) on every
``--scenes`` scene, for ``--seeds`` seeds, interleaved seed by seed, against Mitsuba 3's
``volpath`` (``--ref-spp`` spp over 8 seeds, llvm_ad_rgb, cached; or ``--reference pt``), and
prints each method's final relMSE per seed and the ratio to pt's (> 1: the photon estimator has the
lower error), mean and spread. A reference's own noise adds its floor to every relMSE and pulls
every ratio towards 1; the volume caustic's fireflies make that floor hard to push down, so the
ratios are printed twice: of the raw relMSE, and of relMSE minus the floor (the error against the
true image, in expectation: E|I - R|^2 = E|I - L|^2 + E|R - L|^2 for independent I and R).
``--refs-only`` renders (and caches) the references and stops.

    .venv/bin/python benchmarks/bench_vpm.py --equal-time 15 --res 128 --seeds 3

``--effects single-scattering`` renders only that class with every method (the reference is then
gdlearn's pt, Mitsuba 3 cannot split its image); with ``--scenes scenes/fog-box.xml`` and
``--radius-scale`` it is the thin-medium comparison of the papers (the medium alone):

    .venv/bin/python benchmarks/bench_vpm.py --equal-time 15 --res 128 --scenes scenes/fog-box.xml \
        --effects single-scattering --ref-spp 8192 --radius-scale 0.2 --methods vpm,bre-2d
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402

METHODS = {"vpm": ("vpm", {}), "vpm-knn": ("vpm", {"radii": "knn"}), "bre-3d": ("bre", {"kernel": "3d"}), "bre-2d": ("bre", {"kernel": "2d"}),
           "bre-3d-variable": ("bre", {"kernel": "3d", "radii": "variable"})}
STAGES = ("photons", "build", "gather", "update")


def stage_times(name, scene, a):
    integ_name, opts = METHODS[name]
    integ = make(integ_name, scene, seed=0, photons_per_pass=a.photons, threads=a.threads, **opts)
    c0 = time.perf_counter()
    integ.warmup()
    compile_s = time.perf_counter() - c0
    prev = dict.fromkeys(STAGES, 0.0)
    per = {k: [] for k in STAGES}
    for i in range(a.repeats + 1):
        f = integ.step()
        for k in STAGES:
            if i > 0:
                per[k].append(f.timings[k] - prev[k])
            prev[k] = f.timings[k]
    med = {k: statistics.median(v) for k, v in per.items()}
    st = f.stats
    return compile_s, med, st["volume_photons"] / f.passes, st["volume_photons_gathered"] / f.passes


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scenes/fog-box.xml")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--photons", type=int, default=200_000, help="light paths per pass")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--equal-time", type=float, default=None, metavar="S")
    ap.add_argument("--scenes", default="scenes/fog-box.xml,scenes/medium-cube.xml,scenes/spot-medium.xml,"
                                        "scenes/volume-caustic.xml")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--reference", choices=("mitsuba", "pt"), default="mitsuba")
    ap.add_argument("--ref-spp", type=int, default=16384)
    ap.add_argument("--refs-only", action="store_true")
    ap.add_argument("--effects", default=None, metavar="E1,E2",
                    help="render only these light-transport classes (e.g. single-scattering) with every method; "
                         "the reference is then pt's (Mitsuba 3 cannot split its image by class)")
    ap.add_argument("--radius-scale", type=float, default=1.0,
                    help="every photon estimator's volume radius: this multiple of its default")
    ap.add_argument("--methods", default="vpm,vpm-knn,bre-3d,bre-2d", help="photon estimators of --equal-time")
    a = ap.parse_args(argv)
    if a.equal_time is not None:
        return equal_time_study(a)
    scene = load(a.scene, res=a.res)
    print(f"scene {a.scene} at {a.res}x{a.res}, {a.photons} light paths a pass, {a.threads} threads, median of "
          f"{a.repeats} passes after the first; load average {os.getloadavg()[0]:.2f}")
    print(f"{'method':16s} {'compile':>8s} {'photons':>8s} {'build':>8s} {'gather':>8s} {'update':>8s} "
          f"{'vol. photons':>12s} {'gathered/pass':>13s}")
    for name in METHODS:
        c, med, nv, ng = stage_times(name, scene, a)
        print(f"{name:16s} {c:7.1f}s {med['photons']:7.3f}s {med['build']:7.3f}s {med['gather']:7.3f}s "
              f"{med['update']:7.3f}s {nv:12.0f} {ng:13.0f}")
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


def equal_time_study(a) -> int:
    """pt vs vpm vs bre at equal time (module docstring)."""
    import numpy as np

    from gdlearn.experiments import SceneFile, equal_time
    from gdlearn.experiments.references import mitsuba_reference, render_reference
    from gdlearn.experiments.study import Method

    names = a.methods.split(",")
    effects = {"effects": tuple(a.effects.split(","))} if a.effects else {}
    methods = [Method("pt", "pt", None, tuple(effects.items()))]
    methods += [Method(n, METHODS[n][0], None, tuple(sorted({**METHODS[n][1], "photons_per_pass": a.photons,
                                                             "threads": a.threads, **effects,
                                                             "volume_radius_scale": a.radius_scale}.items())))
                for n in names]
    print(f"equal time {a.equal_time:.1f} s per run, {a.res}x{a.res}, {a.seeds} seeds, {a.photons} light paths a "
          f"pass, effects {a.effects or 'all'}, radius scale {a.radius_scale}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    for path in a.scenes.split(","):
        sf = SceneFile(path, (("res", a.res),))
        t0 = time.perf_counter()
        if a.reference == "mitsuba" and not a.effects:
            ref = mitsuba_reference(sf, spp=a.ref_spp, seeds=range(101, 109), variant="llvm_ad_rgb")
        else:
            ref = render_reference(sf, "pt", spp=a.ref_spp, spp_per_pass=64, **{k: list(v) for k, v in effects.items()})
        print(f"\n{sf.name}: reference {ref.estimator} {ref.spp} spp ({time.perf_counter() - t0:.0f} s, cached "
              f"after), relMSE floor {ref.floor:.2e}", flush=True)
        if a.refs_only:
            continue
        err = {m: [] for m in ["pt"] + names}
        for seed in range(a.seeds):
            st = equal_time(methods, [sf], seconds=a.equal_time, seeds=[seed], references=ref, executor="serial",
                            count=4, spp_per_pass=4)
            for m in err:
                err[m].append(st.select(True, method=m, seed=seed)[0]["relmse"])
        for m in err:
            e = np.array(err[m])
            ratio = np.array(err["pt"]) / e
            clean = np.maximum(np.array(err["pt"]) - ref.floor, 0) / np.maximum(e - ref.floor, 1e-300)
            print(f"  {m:8s} relMSE {e.mean():.3e} (seeds: {', '.join(f'{x:.3e}' for x in e)})  pt / {m}: mean "
                  f"{ratio.mean():.2f}, min {ratio.min():.2f}, max {ratio.max():.2f}; less the floor: mean "
                  f"{clean.mean():.2f}, min {clean.min():.2f}, max {clean.max():.2f}", flush=True)
        print(f"  load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
