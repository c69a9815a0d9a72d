"""``gdlearn render SCENE --integrator pt --spp N --out FILE``: render a scene file to an image.

Stops after ``--spp`` samples per pixel or ``--time`` seconds of rendering (JIT compilation not
counted), whichever comes first. ``--out`` picks the format from its extension (.exr, .png tone-mapped,
.npy linear float); ``--buffers DIR`` also writes every buffer of the final frame (primal, gradients,
half-buffers, variances) as .npy. Ctrl-C stops early and still writes what was accumulated.
For gradient integrators (``--integrator gpt-replay``, ``gpt``, ``gpm``, ``gvpm``, ``gbre``),
``--recon {cv,cv-weighted,l2,l1}`` writes the reconstructed image to ``--out`` instead of the primal
(and ``recon.npy`` beside the buffers).
Scene defaults are overridden with ``--set name=value`` (like ``mitsuba.load_file(path, res=64)``).
"""
from __future__ import annotations

import os
import sys
import time

#: ``--shift`` choices: gdlearn.integrators.path.gpt.SUPPORTED, spelled out so the parser imports no kernels
#: (tests/test_gpt.py checks that the two agree)
SHIFT_CHOICES = ("replay", "replay+reconnection", "halfvector+reconnection", "halfvector+reconnection+manifold",
                 "halfvector+replay+reconnection")
#: ``--shift`` choices of gvpm and gbre (the photon shift, Gruson et al. 2018, Eq. 16)
VOLUME_SHIFT_CHOICES = ("mixed", "simple")

#: integrators that take --photons, --alpha and --radius
PHOTON_INTEGRATORS = ("sppm", "ppm", "gpm", "vpm", "bre", "gvpm", "gbre")
#: option -> (keyword, the integrators it applies to)
PHOTON_OPTIONS = {"--photons": ("photons_per_pass", PHOTON_INTEGRATORS), "--alpha": ("alpha", PHOTON_INTEGRATORS),
                  "--radius": ("radius", PHOTON_INTEGRATORS), "--radius-scale": ("radius_scale", PHOTON_INTEGRATORS),
                  "--direct": ("direct", ("sppm", "ppm")),
                  "--volume-radius": ("volume_radius", ("vpm", "bre", "gvpm", "gbre")),
                  "--volume-radius-scale": ("volume_radius_scale", ("vpm", "bre", "gvpm", "gbre")),
                  "--neighbors": ("neighbors", ("vpm", "bre", "gvpm", "gbre")),
                  "--transport": ("transport", ("pt", "vpm", "bre", "gvpm", "gbre")),
                  "--samples": ("samples", ("vpm", "gvpm")),
                  "--kernel": ("kernel", ("bre", "gbre")), "--radii": ("radii", ("vpm", "bre")),
                  "--walk": ("walk", ("gvpm", "gbre"))}


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("render", help="render a scene file to an image",
                              description=__doc__.splitlines()[0])
    p.add_argument("scene", help="scene file (Mitsuba 3 XML subset, see scenes/README.md)")
    p.add_argument("--integrator", default="pt", help="estimator name (default: pt)")
    p.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the scene's sampler)")
    p.add_argument("--time", type=float, default=None, metavar="SECONDS", help="stop after this much rendering time")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--effects", default=None, help="comma list of effects to render (see `gdlearn effects`)")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    p.add_argument("--spp-per-pass", type=int, default=1, help="samples per pixel in one progressive pass")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a scene <default>, e.g. --set res=64 (repeatable)")
    p.add_argument("--out", required=True, help="output image: .exr, .png or .npy")
    p.add_argument("--buffers", default=None, metavar="DIR", help="also write every buffer as DIR/<name>.npy")
    p.add_argument("--recon", default="none", choices=("none", "cv", "cv-weighted", "l2", "l1"),
                   help="gradient integrators: write the image reconstructed by this solver to --out "
                        "(default none: the primal image)")
    p.add_argument("--shift", default=None, choices=SHIFT_CHOICES + VOLUME_SHIFT_CHOICES, metavar="POLICY",
                   help="gpt: shift-mapping policy, one of " + ", ".join(SHIFT_CHOICES) + " (default: "
                        "halfvector+replay+reconnection; halfvector+reconnection+manifold walks specular chains where "
                        "the effects plan renders them, at a higher cost per sample); gvpm/gbre: the photon shift, mixed "
                        "(default, Gruson et al. 2018 Eq. 16; gbre --kernel 3d) or simple (gbre --kernel 2d: the "
                        "ray-frame copy, its default)")
    # photon estimators (sppm, ppm, vpm, bre); a pass takes 2 camera samples per pixel, so --spp counts passes too
    p.add_argument("--photons", type=int, default=None, metavar="N",
                   help="sppm/ppm/vpm/bre/gvpm/gbre: light paths emitted per pass (default 100000)")
    p.add_argument("--alpha", type=float, default=None,
                   help="photon integrators: radius reduction alpha (default 0.7; gpm 0.9, Hua et al. 2017's)")
    p.add_argument("--radius", type=float, default=None, metavar="R",
                   help="photon integrators: initial surface radius in scene units, the same for every pixel "
                        "(default: --radius-scale x each pixel's footprint)")
    p.add_argument("--radius-scale", type=float, default=None, metavar="S",
                   help="photon integrators: initial surface radius in pixel footprints (default 1; gpm 0.35: "
                        "the gradients afford a smaller kernel, see gdlearn.integrators.photon.gpm)")
    p.add_argument("--direct", choices=("photons", "nee"), default=None,
                   help="sppm/ppm: direct light from photons (default) or by emitter sampling at the gather point")
    p.add_argument("--volume-radius", type=float, default=None, metavar="R",
                   help="vpm/bre/gvpm/gbre: initial volume kernel radius in scene units (default: "
                        "--volume-radius-scale x the median distance to the --neighbors-th nearest volume photon)")
    p.add_argument("--volume-radius-scale", type=float, default=None, metavar="S",
                   help="vpm/bre/gvpm/gbre: initial volume radius as a multiple of that median distance (default 1; "
                        "gvpm/gbre 0.2: the gradients afford a smaller kernel, see gdlearn.integrators.photon.gvpm)")
    p.add_argument("--neighbors", type=int, default=None, metavar="N",
                   help="vpm/bre/gvpm/gbre: photons per kernel that set the default volume radius, and the k of "
                        "k-NN and variable radii (default 32)")
    p.add_argument("--transport", choices=("all", "media"), default=None,
                   help="pt/vpm/bre/gvpm/gbre: the full image (default; gvpm/gbre: surface gradients by GPM's "
                        "shifts) or only light transport ending in the medium (pt: the photon estimators' reference)")
    p.add_argument("--samples", type=int, default=None, metavar="K",
                   help="vpm/gvpm: distance samples per camera path (default 8)")
    p.add_argument("--kernel", choices=("2d", "3d"), default=None,
                   help="bre/gbre: a biweight disc facing the ray (2d) or a uniform ball (3d, the default)")
    p.add_argument("--radii", choices=("fixed", "knn", "variable"), default=None,
                   help="bre: photon radii fixed (default), k-NN, or variable kernels (Jarosz et al. 2008); "
                        "vpm: progressive per-pixel radii (fixed, the default) or a k-NN radius at each sample")
    p.add_argument("--walk", choices=("relaxed", "exact"), default=None,
                   help="gvpm/gbre: the manifold walk of volume photons through specular chains, exact (converged "
                        "and reversible; the default) or relaxed (accepted inside the offset kernel, Gruson et al. "
                        "2018 Sec. 6.1: biased, consistent)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _defaults(pairs):
    out = {}
    for s in pairs:
        if "=" not in s:
            raise SystemExit(f"gdlearn render: --set expects NAME=VALUE, got {s!r}")
        k, v = s.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def run(args) -> int:
    from gdlearn.integrators import make, render
    from gdlearn.io import write_image
    from gdlearn.scene.effects import EffectsError
    from gdlearn.io.images import _ext
    from gdlearn.scene.load import load

    try:
        _ext(args.out)
    except ValueError as err:
        print(f"gdlearn render: {err}", file=sys.stderr)
        return 2
    scene = load(args.scene, **_defaults(args.set))
    for w in scene.warnings:
        print(f"warning: {w}", file=sys.stderr)
    opts = dict(seed=args.seed, spp_per_pass=args.spp_per_pass)
    if args.effects is not None:
        opts["effects"] = args.effects
    if args.threads is not None:
        opts["threads"] = args.threads
    if args.shift is not None:
        owner = "gvpm/gbre" if args.shift in VOLUME_SHIFT_CHOICES else "gpt"
        if args.integrator not in owner.split("/"):
            print(f"gdlearn render: --shift {args.shift} applies to --integrator {owner}, not {args.integrator}",
                  file=sys.stderr)
            return 2
        opts["shift"] = args.shift
    for flag, (key, owners) in PHOTON_OPTIONS.items():
        value = getattr(args, flag[2:].replace("-", "_"))
        if value is None:
            continue
        if args.integrator not in owners:
            print(f"gdlearn render: {flag} applies to --integrator {'/'.join(owners)}, not {args.integrator}",
                  file=sys.stderr)
            return 2
        opts[key] = value
    try:
        integ = make(args.integrator, scene, **opts)
    except EffectsError as err:
        print(f"gdlearn render: {err}", file=sys.stderr)
        return 2
    except ValueError as err:
        print(f"gdlearn render: {err}", file=sys.stderr)
        return 2
    spp = args.spp if (args.spp is not None or args.time is not None) else scene.sensor.spp
    t0 = time.perf_counter()
    try:
        integ.warmup()          # JIT first, so the message below means "samples are being taken"
        print(f"gdlearn render: compiled in {time.perf_counter() - t0:.2f} s; rendering "
              f"{f'{spp} spp' if spp else ''}{' / ' if spp and args.time else ''}"
              f"{f'{args.time} s' if args.time else ''} (Ctrl-C saves what is done)", file=sys.stderr, flush=True)
        frame = render(integ, spp=spp, seconds=args.time, progress=not args.no_progress)
    except KeyboardInterrupt:      # during JIT compilation or the first pass: nothing accumulated yet
        print("gdlearn render: interrupted before the first pass; nothing written", file=sys.stderr)
        return 130
    image = frame.primal
    if args.recon != "none":
        if frame.gx is None or frame.gy is None:
            print(f"gdlearn render: --recon {args.recon} needs a gradient integrator (e.g. --integrator "
                  f"gpt-replay); {args.integrator!r} makes only a primal image. Drop --recon.", file=sys.stderr)
            return 2
        from gdlearn.experiments.solvers import final_image
        image = final_image(frame, args.recon)
    write_image(args.out, image)
    if args.buffers:
        os.makedirs(args.buffers, exist_ok=True)
        import numpy as np
        for name, buf in frame.buffers().items():
            if buf is not None:
                np.save(os.path.join(args.buffers, f"{name}.npy"), buf)
        if args.recon != "none":
            np.save(os.path.join(args.buffers, "recon.npy"), image)
    wall = time.perf_counter() - t0
    msg = (f"{args.out}: {frame.spp} spp in {frame.elapsed:.2f} s rendering "
           f"(+{frame.timings.get('compile', 0.0):.2f} s JIT, {wall:.2f} s total)")
    if frame.stats.get("nonfinite_samples") or frame.stats.get("nonfinite_pixels"):
        msg += f"; dropped non-finite: {frame.stats.get('nonfinite_samples', 0)} samples"
    if frame.interrupted:
        print(f"gdlearn render: interrupted; saved what was accumulated. {msg}", file=sys.stderr)
        return 130
    print(msg, file=sys.stderr)
    return 0
