"""``gdlearn compare SCENE --methods pt,gpt --time SECONDS``: an equal-time study from the shell.

Runs every method for the same wall-clock budget (JIT compile excluded, reconstruction included)
on ``--seeds`` seeds, measures relMSE against a reference at geometrically spaced snapshots, prints
a summary table and optionally writes the tidy records (``--csv``) and a figure (``--plot``).
See :mod:`gdlearn.experiments` and the book chapter "What accuracy costs".

SCENE is a scene file, or ``toy`` / ``toy:WxH`` for the analytic toy image of
:mod:`gdlearn.teaching.toy` (methods ``toy-pt``, ``toy-gpt``; its exact image is the reference).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

TOY_METHODS = {"toy-pt": "gdlearn.teaching.toy:ToyPrimal",
               "toy-gpt": "gdlearn.teaching.toy:ToyGradient"}


def add_parser(sub) -> None:
    p = sub.add_parser("compare", help="equal-time comparison of estimators (relMSE vs time)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="scene file, or toy[:WxH]")
    p.add_argument("--methods", required=True,
                   help="comma-separated estimators: registry names (pt, gpt, ...), name+solver "
                        "(gpt+l2), module:Class, with integrator options as :key=value (bre:kernel=2d)")
    budget = p.add_mutually_exclusive_group(required=True)
    budget.add_argument("--time", type=float, metavar="SECONDS", help="equal-time budget per run")
    budget.add_argument("--passes", type=int, help="equal-sample budget: passes per run")
    p.add_argument("-D", "--define", action="append", default=[], metavar="NAME=VALUE",
                   help="override a <default> parameter of the scene file, e.g. -D res=64 "
                        "(repeatable; as mitsuba -D)")
    p.add_argument("--seeds", type=int, default=1, help="independent runs per method (default 1)")
    p.add_argument("--reference", default="auto",
                   help="reference image file (.npz/.npy/.exr), 'mitsuba', or 'auto' (default: a "
                        "cached long run of --reference-method)")
    p.add_argument("--reference-method", default="pt", help="estimator for --reference auto")
    p.add_argument("--reference-spp", type=int, default=1024, help="spp of the reference (1024)")
    p.add_argument("--solver", default=None, choices=["cv", "cv-weighted", "l2", "l1"],
                   help="reconstruction for methods that produce gradients")
    p.add_argument("--spp-per-pass", type=int, default=1, help="samples per pixel per pass")
    p.add_argument("--snapshots", type=int, default=12, help="snapshots per run (default 12)")
    p.add_argument("--executor", default="local",
                   help="local (default, 1 worker), local:N, serial, dask (LocalCluster) or a Dask "
                        "scheduler address tcp://host:port")
    p.add_argument("--baseline", default=None, help="method the ratios refer to (default: first)")
    p.add_argument("--plot", default=None, metavar="PNG", help="write the summary figure here")
    p.add_argument("--csv", default=None, metavar="CSV", help="write the tidy records here")
    p.set_defaults(func=run)


def _toy(spec: str):
    from gdlearn.teaching.toy import ToyScene
    if spec == "toy":
        return ToyScene()
    try:
        w, h = (int(v) for v in spec.split(":", 1)[1].lower().split("x"))
    except ValueError:
        raise SystemExit(f"gdlearn compare: cannot read toy size in {spec!r}; use toy:48x32") from None
    return ToyScene(w, h)


def _defines(items) -> tuple:
    out = []
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name:
            raise SystemExit(f"gdlearn compare: -D {item!r} is not NAME=VALUE (e.g. -D res=64)")
        out.append((name.strip(), value.strip()))
    return tuple(sorted(out))


def _reference(args, scene, is_toy):
    from gdlearn.experiments import references as refs
    if is_toy and args.reference == "auto":
        return refs.Reference(scene.truth(), np.zeros((scene.height, scene.width, 3)), None,
                              "analytic")
    if args.reference == "auto":
        print(f"reference: {args.reference_spp} spp of {args.reference_method} (cached in "
              f"{refs.cache_dir()}; the first time this takes a while)", file=sys.stderr)
        return refs.render_reference(scene, TOY_METHODS.get(args.reference_method,
                                                            args.reference_method),
                                     spp=args.reference_spp)
    if args.reference == "mitsuba":
        if is_toy:
            raise SystemExit("gdlearn compare: Mitsuba cannot render the toy scene; use --reference auto")
        return refs.mitsuba_reference(scene, spp=args.reference_spp)
    return refs.load_reference(args.reference)


def run(args) -> int:
    from gdlearn.experiments import plots, study as st

    is_toy = args.scene == "toy" or args.scene.startswith("toy:")
    scene = _toy(args.scene) if is_toy else st.SceneFile(args.scene, _defines(args.define))
    methods = []
    for spec in (m.strip() for m in args.methods.split(",") if m.strip()):
        m = st.Method.parse(spec, args.solver)
        methods.append(replace(m, estimator=TOY_METHODS.get(m.estimator, m.estimator)))
    ref = _reference(args, scene, is_toy)
    print(f"reference: {ref.estimator}, spp {ref.spp}, noise floor relMSE {ref.floor:.3g}",
          file=sys.stderr)
    study = st.equal_time(methods, [scene], seconds=args.time, passes=args.passes,
                          seeds=args.seeds, references={st.scene_name(scene): ref},
                          executor=args.executor, count=args.snapshots,
                          spp_per_pass=args.spp_per_pass)
    baseline = args.baseline or methods[0].label
    ratios = study.equal_time_ratios(baseline)
    # the ratio of the methods' own errors, which a noisy reference pulls towards 1
    less = study.equal_time_ratios(baseline, less_floor=True)      # NaN where the noise is unknown
    name = st.scene_name(scene)
    print(f"{'method':<24}{'relMSE':>12}{'seconds':>10}{'passes':>8}{'spp':>8}{'compile s':>10}"
          f"{'ratio':>8}{'less floor':>11}")
    for m in study.methods():
        fin = study.select(True, method=m, scene=name)
        print(f"{m:<24}{np.mean([r['relmse'] for r in fin]):>12.4g}"
              f"{np.mean([r['seconds'] for r in fin]):>10.3f}{np.mean([r['passes'] for r in fin]):>8.0f}"
              f"{np.mean([r['spp'] for r in fin]):>8.0f}"
              f"{np.mean([r['compile_seconds'] for r in fin]):>10.2f}{ratios[(m, name)]:>7.2f}x"
              f"{less[(m, name)]:>10.2f}x")
    if args.csv:
        print(f"records: {study.to_csv(args.csv)}", file=sys.stderr)
    if args.plot:
        import matplotlib
        matplotlib.use("Agg")
        fig = plots.summary(study, name, ref.image, baseline)
        fig.savefig(args.plot, dpi=110)
        print(f"figure: {args.plot}", file=sys.stderr)
    return 0
