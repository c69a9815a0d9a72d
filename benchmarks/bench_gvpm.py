"""G-VPM's cost per pass against VPM's, light transport ending in the medium (Gruson et al. 2018 report
G-VPM about 1.3x VPM's time per iteration, Sec. 6.3).

Per scene, JIT warmed, the passes of vpm, gvpm (mixed shift) and gvpm (simple shift) *interleaved*
(vpm, gvpm, gvpm-simple, vpm, ...; all see the same load), the median time of a pass of each after
the first (which also measures the initial radii), their ratios, the stage split, and the photon-shift
statistics (null / mixed / reconnected / failed, per gathered photon and neighbour).

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gvpm.py [--scenes scenes/fog-box.xml,...]
        [--res 128] [--photons 100000] [--repeats 3] [--threads 2]

``--equal-time S``: vpm, gvpm+l1, gvpm+l2 (the mixed shift) and bre (3D kernel), all with
``--transport media``, for S seconds each (JIT excluded, the reconstruction included: the
experiments module stops rendering early enough for it) on every ``--scenes`` scene, ``--seeds``
seeds interleaved seed by seed, all at ``--threads`` threads. The reference (``--ref``) is by default
pt with ``transport="media"`` (``--ref-spp`` samples per pixel, seed 1000003, independent of the
runs): unbiased, so it holds no kernel's blur (benchmarks/README.md, "The vpm reference cannot judge
a kernel's size"). ``--ref lt`` (the volume caustic: pt finds it only when a phase sample leaves
through the lens towards the small light) takes light tracing (``make("lt")``, ``--ref-passes`` x
``--ref-photons`` light paths) where the camera sees the medium directly and pt's reference where
it may look through glass. ``--ref vpm`` takes a long vpm run instead (``--ref-passes`` passes of
``--ref-photons`` light paths at ``--ref-radius-scale`` x the default radius), the reference of the
studies before 2026-12-05. Either is rendered once and cached on disk under the benchmark's own
folder (``$GDLEARN_CACHE`` or ``~/.cache/gdlearn``, then ``bench_gvpm/``), keyed by the scene, the
resolution, the budget and the sources of its pipeline (so an edit of the G-VPM kernels keeps it).
``--methods`` picks others, the first the ratios' base (``name@S`` starts from S x the default
volume radius, e.g. ``vpm@0.35``): G-BRE's study is ``--methods
bre-3d,gbre+l1,gbre-2d+l1`` (gbre: 3D kernel, mixed shift; gbre-2d: the ray-frame copy; photon
subsets on; bre-2d is there too; ``gvpm-relaxed+l1``, ``gbre-relaxed+l1`` and their l2 twins walk
volume photons' chains relaxed, Gruson et al. 2018 Sec. 6.1; ``gvpm+cv``, ``gvpm+cv-weighted``,
``gbre+cv``, ``gbre+cv-weighted`` reconstruct by (weighted) control variates instead,
:mod:`gdlearn.experiments.solvers`; ``gbre-nosub+l1``, ``gbre-nosub+l2``, ``gbre-nosub+cv``,
``gbre-nosub+cv-weighted`` gather every photon at every pixel, ``subsets=False``). Prints each
method's final relMSE per seed, the ratio base / method (> 1: lower error than the base), its mean,
min and max over the seeds, and the same with the reference's noise floor subtracted from both
errors (E|I - R|^2 = E|I - L|^2 + E|R - L|^2 for an independent reference R). The methods' order
rotates from seed to seed. ``--refs-only`` renders (and caches) the references and stops: keep each
locked run under a few minutes by rendering the references, then each scene (or a part of its
seeds, ``--first-seed``), in runs of their own.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gvpm.py --equal-time 20 --res 128 \
        --seeds 3 --scenes scenes/spot-medium.xml

``--sweep SCALES``: the first volume radius, ``volume_radius_scale`` x the default (the median
distance to the 32nd volume photon), for each scale and each of ``--methods`` at equal time
(``--equal-time``, default 20 s), ``--seeds`` seeds: the final relMSE split by
``experiments.metrics.bias_variance`` into the kernel's squared bias (the reference's floor and
blur included) and one run's variance, as ``bench_gpm.py --sweep`` does for surfaces. The vpm
reference would carry its own kernel's blur (a sharper estimate reads as biased against it), hence
the pt reference.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gvpm.py --sweep 0.35,0.6,1 --methods vpm,gvpm+l1 \
        --res 128 --photons 50000 --seeds 3 --scenes scenes/spot-medium.xml
"""
from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402

SCENES = "scenes/fog-box.xml,scenes/spot-medium.xml"
KINDS = ("null", "mixed", "reconnected", "failed", "manifold")


def interleaved_times(integs: dict, repeats: int):
    """Compile every integrator, then run their passes interleaved (a, b, c, a, ...: all see the same
    load); returns (the median seconds of a pass after the first, per name; each one's last PassResult)."""
    for integ in integs.values():
        integ.compile()
    times = {n: [] for n in integs}
    last = {}
    for i in range(repeats + 1):
        for n, integ in integs.items():
            t0 = time.perf_counter()
            res = integ.render_pass(i)
            if i > 0:
                times[n].append(time.perf_counter() - t0)
            last[n] = res
    return {n: statistics.median(v) for n, v in times.items()}, last


def old_vs_new(kernels: dict, call, allocate, repeats: int):
    """Time a camera pass's kernels ``{"old": .., "new": ..}`` on the same inputs, interleaved (old,
    new, old, ...: both see the same load), the first round untimed (it compiles the frozen
    reference kernel of tests/). ``call(rows, out)`` runs one kernel into ``out = allocate()``.
    Returns (a line: medians, minima, their ratio, whether every buffer of the two is equal; the
    last outputs per name)."""
    import numpy as np

    times = {n: [] for n in kernels}
    outs = {}
    for i in range(repeats + 1):
        for n, rows in kernels.items():
            out = allocate()
            t0 = time.perf_counter()
            call(rows, out)
            if i > 0:
                times[n].append(time.perf_counter() - t0)
            outs[n] = out
    same = all(np.array_equal(x, y) for x, y in zip(outs["old"], outs["new"]))
    med = {n: statistics.median(v) for n, v in times.items()}
    return (f"kernel old {med['old']:6.3f} s (min {min(times['old']):.3f})  new {med['new']:6.3f} s (min "
            f"{min(times['new']):.3f})  old/new {med['old'] / med['new']:5.2f}  array-equal {same}"), outs


def shift_line(name: str, res) -> str:
    """The stage split and photon-shift statistics of a gradient pass (per gathered photon and neighbour)."""
    st = res.stats
    c = {k: st.get(f"photon_shifts_{k}", 0) for k in KINDS}
    tot = max(c["null"] + c["reconnected"] + c["failed"] + c["manifold"], 1)
    stage = {k: res.timings.get(k, 0.0) for k in ("photons", "build", "gather")}
    return (f"    {name:12s} stages: light paths {stage['photons']:.3f} s, build {stage['build']:.3f} s, gather "
            f"{stage['gather']:.3f} s; photon shifts: null {c['null'] / tot:.1%}, reconnected "
            f"{c['reconnected'] / tot:.1%} (reflected by Eq. 16 {c['mixed'] / tot:.1%}: reconnected or walked), walked "
            f"{c['manifold'] / tot:.1%}, failed {c['failed'] / tot:.1%}; gathered photons {st['volume_photons_gathered']}")


def pass_times(path, a) -> None:
    scene = load(path, res=a.res)
    common = dict(seed=0, photons_per_pass=a.photons, threads=a.threads, transport="media")
    integs = {"vpm": make("vpm", scene, **common), "gvpm": make("gvpm", scene, **common),
              "gvpm-simple": make("gvpm", scene, shift="simple", **common)}
    med, last = interleaved_times(integs, a.repeats)
    line = f"{os.path.basename(path):18s} " + "  ".join(f"{n} {t:6.3f} s/pass" for n, t in med.items())
    line += f"  gvpm/vpm {med['gvpm'] / med['vpm']:5.2f}  simple/vpm {med['gvpm-simple'] / med['vpm']:5.2f}"
    print(line, flush=True)
    for n in ("gvpm", "gvpm-simple"):
        print(shift_line(n, last[n]), flush=True)


#: the sources a vpm reference depends on (its cache key, references.source_digest): VPM's camera
#: pass, volume estimates, photons
REF_SOURCES = ("integrators/photon/volumetric.py", "integrators/photon/volume_gather.py",
               "integrators/photon/volume_estimates.py", "integrators/photon/camera_beams.py",
               "integrators/photon/sppm.py", "photons", "kernels/media")
REF_SEED = 1_000_003
#: the sources a pt reference depends on: the volume path tracer and the effects classes
PT_REF_SOURCES = ("integrators/path/pt.py", "integrators/path/volume.py", "integrators/path/surface.py",
                  "kernels/pathclass.py", "kernels/media", "kernels/bsdf", "kernels/lights.py")


def _digest(path, text: str, sources) -> str:
    """A reference's cache key: ``text`` (its kind and budget), the scene file and ``sources``."""
    from gdlearn.experiments.references import source_digest
    h = hashlib.sha256(text.encode())
    h.update(open(path, "rb").read())
    h.update(source_digest(sources).encode())
    return h.hexdigest()[:20]


def _ref_key(path, a) -> str:
    # the reference's radius enters the key only when it is not the default, so old caches stay valid
    scale = "" if a.ref_radius_scale == 1.0 else f" {a.ref_radius_scale!r}"
    return _digest(path, f"{a.res} {a.ref_passes} {a.ref_photons} {REF_SEED} {a.threads}{scale}", REF_SOURCES)


def reference(path, a):
    """The reference of ``path`` (module docstring, ``--ref``), from the cache or rendered now."""
    import numpy as np

    from gdlearn.experiments.references import Reference, cache_dir, load_reference
    from gdlearn.integrators.base import render

    folder = cache_dir().parent / "bench_gvpm"
    key = {"vpm": _ref_key, "pt": _pt_ref_key, "lt": _lt_ref_key}[a.ref](path, a)
    file = folder / f"{os.path.basename(path)}-{a.res}-{key}.npz"
    if file.is_file():
        return load_reference(file), 0.0
    t0 = time.perf_counter()
    scene = load(path, res=a.res)
    if a.ref == "vpm":
        integ = make("vpm", scene, seed=REF_SEED, photons_per_pass=a.ref_photons, threads=a.threads,
                     transport="media", volume_radius_scale=a.ref_radius_scale)
        frame = render(integ, spp=2 * a.ref_passes)
        image, variance, spp = frame.primal, frame.variance(), frame.spp
    elif a.ref == "pt":
        frame = render(make("pt", scene, seed=REF_SEED, transport="media", threads=a.threads, spp_per_pass=64),
                       spp=a.ref_spp)
        image, variance, spp = frame.primal, frame.variance(), frame.spp
    else:
        image, variance, spp = _lt_reference(path, scene, a)
    if not np.isfinite(image).all():
        raise RuntimeError(f"{path}: the {a.ref} reference has non-finite pixels")
    ref = Reference(image, variance, spp, a.ref, file.stem)
    folder.mkdir(parents=True, exist_ok=True)
    ref.save(file)
    return ref, time.perf_counter() - t0


def _lt_reference(path, scene, a):
    """Light tracing where the camera sees the medium directly, pt where it may look through a
    specular surface (``light_tracing.specular_view_mask``): (image, variance, passes)."""
    import numpy as np

    from gdlearn.integrators.base import render
    from gdlearn.integrators.photon.light_tracing import specular_view_mask

    integ = make("lt", scene, seed=REF_SEED, photons_per_pass=a.ref_photons, threads=a.threads)
    frame = render(integ, passes=a.ref_passes)
    mask = specular_view_mask(integ.setup.sa, integ.setup.width, integ.setup.height)[..., None]
    pa = argparse.Namespace(**{**vars(a), "ref": "pt"})
    pt, _ = reference(path, pa)
    print(f"  lt reference: {frame.passes} passes x {a.ref_photons} light paths, pt ({pt.spp} spp) in the "
          f"{int(mask.sum())} pixels that may see the medium through a specular surface", flush=True)
    return (np.where(mask, pt.image, frame.primal), np.where(mask, pt.variance, frame.variance()), frame.passes)


def _pt_ref_key(path, a) -> str:
    return _digest(path, f"pt media {a.res} {a.ref_spp} {REF_SEED}", PT_REF_SOURCES)


def _lt_ref_key(path, a) -> str:
    return _digest(path, f"lt {a.res} {a.ref_passes} {a.ref_photons} {REF_SEED} {_pt_ref_key(path, a)}",
                   ("integrators/photon/light_tracing.py", "photons") + PT_REF_SOURCES)


def ref_line(path, ref, took, a) -> str:
    """What the reference is, for the reports."""
    what = {"vpm": f"vpm {ref.spp // 2} passes x {a.ref_photons} light paths at {a.ref_radius_scale:g} x the default "
                   f"volume radius", "pt": f"pt --transport media, {ref.spp} spp",
            "lt": f"lt {ref.spp} passes x {a.ref_photons} light paths (pt where glass is seen)"}[a.ref]
    return (f"{os.path.basename(path)}: reference {what} ({'cached' if took == 0 else f'{took:.0f} s'}), relMSE floor "
            f"{ref.floor:.2e}")


def methods(a, extra=()) -> dict:
    """The methods ``--methods`` may name, every one with ``--transport media`` and ``extra`` options."""
    from gdlearn.experiments.study import Method

    opts = (("photons_per_pass", a.photons), ("threads", a.threads), ("transport", "media")) + tuple(extra)
    k3, k2 = (("kernel", "3d"),), (("kernel", "2d"),)
    every = {"vpm": Method("vpm", "vpm", None, opts), "gvpm+l1": Method("gvpm+l1", "gvpm", "l1", opts),
             "gvpm+l2": Method("gvpm+l2", "gvpm", "l2", opts),
             "bre-3d": Method("bre-3d", "bre", None, opts + k3), "bre-2d": Method("bre-2d", "bre", None, opts + k2),
             "gbre+l1": Method("gbre+l1", "gbre", "l1", opts + k3 + (("shift", "mixed"),)),
             "gbre+l2": Method("gbre+l2", "gbre", "l2", opts + k3 + (("shift", "mixed"),)),
             "gbre-2d+l1": Method("gbre-2d+l1", "gbre", "l1", opts + k2)}
    for est in ("gvpm", "gbre"):     # the other reconstructions of experiments.solvers
        for sol in ("cv", "cv-weighted"):
            m = every[f"{est}+l1"]
            every[f"{est}+{sol}"] = Method(f"{est}+{sol}", m.estimator, sol, m.options)
    for name in ("gvpm+l1", "gvpm+l2", "gbre+l1", "gbre+l2"):     # Gruson et al.'s relaxed walk, not the exact one
        est, _, sol = name.partition("+")
        m = every[name]
        every[f"{est}-relaxed+{sol}"] = Method(f"{est}-relaxed+{sol}", m.estimator, m.solver,
                                               m.options + (("walk", "relaxed"),))
    for sol in ("l1", "l2", "cv", "cv-weighted"):   # every pixel gathers every photon (no photon subsets)
        m = every[f"gbre+{sol}"]
        every[f"gbre-nosub+{sol}"] = Method(f"gbre-nosub+{sol}", m.estimator, m.solver,
                                            m.options + (("subsets", False),))
    for name in a.methods.split(","):
        base, _, scale = name.partition("@")       # "vpm@0.35": vpm from 0.35 x the default volume radius
        if base not in every:
            raise SystemExit(f"--methods {a.methods}: choose from {', '.join(every)} (name@S: from S x the default "
                             "volume radius); the first is the ratios' base")
        if scale:
            m = every[base]
            every[name] = Method(name, m.estimator, m.solver, m.options + (("volume_radius_scale", float(scale)),))
    return every


def radius_sweep(a) -> int:
    """Bias and variance against the first volume radius (module docstring, ``--sweep``)."""
    from dataclasses import replace

    from gdlearn.experiments import SceneFile, bias_variance, equal_time

    seconds = a.equal_time or 20.0
    print(f"volume radius sweep: {seconds:.1f} s per run, {a.res}x{a.res}, {a.seeds} seeds, {a.photons} light paths "
          f"a pass, transport media; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    for path in a.scenes.split(","):
        ref, took = reference(path, a)
        print("\n" + ref_line(path, ref, took, a), flush=True)
        sf = SceneFile(path, (("res", a.res),))
        for scale in (float(x) for x in a.sweep.split(",")):
            every = methods(a, (("volume_radius_scale", scale),))
            for name in a.methods.split(","):
                m = replace(every[name], label=f"{name}@{scale:g}")
                st = equal_time([m], [sf], seconds=seconds, seeds=a.seeds, references=ref, executor="serial", count=2)
                bv = bias_variance(st.seed_images(m.label, sf.name), ref.image)
                passes = [r["passes"] for r in st.select(True, method=m.label)]
                print(f"  {name:10s} volume_radius_scale {scale:5.2f}: relMSE {bv['relmse']:.3e} = bias^2 "
                      f"{bv['bias2']:.3e} + variance {bv['variance']:.3e}; passes {', '.join(map(str, passes))}",
                      flush=True)
        print(f"  load average {os.getloadavg()[0]:.2f}", flush=True)
    return 0


def equal_time_study(a) -> int:
    """vpm vs gvpm+l1, gvpm+l2 and bre-3d at equal time, or any ``--methods`` against the first
    (module docstring)."""
    import numpy as np

    from gdlearn.experiments import SceneFile, equal_time

    every = methods(a)
    names = a.methods.split(",")
    base_name = names[0]
    print(f"equal time {a.equal_time:.1f} s per run, {a.res}x{a.res}, {a.seeds} seeds, {a.photons} light paths a "
          f"pass, {a.threads} threads, transport media; load average {os.getloadavg()[0]:.2f} on "
          f"{os.cpu_count()} cores", flush=True)
    for path in a.scenes.split(","):
        ref, took = reference(path, a)
        print("\n" + ref_line(path, ref, took, a), flush=True)
        if a.refs_only:
            continue
        sf = SceneFile(path, (("res", a.res),))
        err = {m: [] for m in names}
        passes = {m: [] for m in names}
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            # the methods' order rotates from seed to seed: a change of the machine's load during the
            # run (other engineers' jobs) then does not always hit the same method
            order = names[seed % len(names):] + names[:seed % len(names)]
            st = equal_time([every[n] for n in order], [sf], seconds=a.equal_time, seeds=[seed], references=ref,
                            executor="serial", count=4)
            for m in names:
                rec = st.select(True, method=m, seed=seed)[0]
                err[m].append(rec["relmse"])
                passes[m].append(rec["passes"])
        base = np.array(err[base_name])
        for m in names:
            e = np.array(err[m])
            ratio = base / e
            # less the floor: only where both errors exceed it (else the reference's noise dominates: n/a)
            ok = (base > ref.floor) & (e > ref.floor)
            clean = (base[ok] - ref.floor) / (e[ok] - ref.floor)
            less = (f"mean {clean.mean():.2f}, min {clean.min():.2f}, max {clean.max():.2f} ({ok.sum()} seeds)"
                    if ok.any() else "n/a (an error under the floor)")
            print(f"  {m:8s} relMSE {e.mean():.3e} (seeds: {', '.join(f'{x:.3e}' for x in e)}; passes "
                  f"{', '.join(str(p) for p in passes[m])})  {base_name} / {m}: mean {ratio.mean():.2f}, min "
                  f"{ratio.min():.2f}, max {ratio.max():.2f}; less the floor: {less}", flush=True)
        print(f"  load average {os.getloadavg()[0]:.2f}", flush=True)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=SCENES)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--photons", type=int, default=100_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--equal-time", type=float, default=None, metavar="S")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1 (split a "
                                                             "study into locked runs of a few minutes)")
    p.add_argument("--methods", default="vpm,gvpm+l1,gvpm+l2,bre-3d",
                   help="of --equal-time, the first the ratios' base (G-BRE's study: bre-3d,gbre+l1,gbre-2d+l1)")
    p.add_argument("--ref", choices=("pt", "lt", "vpm"), default="pt",
                   help="the reference: pt --transport media (unbiased, the default); lt, light tracing where the camera "
                        "sees the medium directly and pt elsewhere (unbiased; for volume caustics, which pt finds "
                        "rarely; --ref-passes x --ref-photons light paths); or a long vpm run (it carries its kernel's "
                        "blur)")
    p.add_argument("--ref-spp", type=int, default=65536, help="samples per pixel of the pt reference")
    p.add_argument("--ref-passes", type=int, default=64, help="passes of the vpm reference")
    p.add_argument("--ref-photons", type=int, default=200_000, help="light paths a pass of the vpm reference")
    p.add_argument("--refs-only", action="store_true")
    p.add_argument("--ref-radius-scale", type=float, default=1.0,
                   help="the reference's first volume radius, x the default (smaller: less of its own blur)")
    p.add_argument("--sweep", default=None, metavar="SCALES",
                   help="first volume radii, x the default (module docstring)")
    a = p.parse_args(argv)
    if a.sweep:
        return radius_sweep(a)
    if a.refs_only and a.equal_time is None:
        p.error("--refs-only renders the references of an equal-time study: give --equal-time S too")
    if a.equal_time is not None:
        return equal_time_study(a)
    for path in a.scenes.split(","):
        pass_times(path, a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
