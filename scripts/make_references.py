#!/usr/bin/env python
"""Render the Mitsuba 3 reference images the cross-check tests compare gdlearn against.

For every case of :func:`gdlearn.crosscheck.store.reference_cases` (each shipped ``scenes/*.xml`` and
``scenes/test/*.xml`` with its own settings, plus the ``max_depth = 2`` cases that gdlearn's
``--effects direct`` must equal) this renders the scene with Mitsuba 3 at 32 x 32 pixels with K
independent seeds and stores the mean image and its per-pixel standard error in
``tests/references/<case>.npz`` (float32, ~25 KB), together with the settings and the scene's hash.

    .venv/bin/python scripts/make_references.py                 # every case (~3 min on 2 cores)
    .venv/bin/python scripts/make_references.py --only cornell-box fog-box.direct
    .venv/bin/python scripts/make_references.py --check         # list missing / stale references

The reference must be much less noisy than the gdlearn render it is compared with, so that the
comparison's power comes from gdlearn's own noise: the defaults (32 seeds x 256 spp = 8192 spp per
pixel) are several times the samples the test renders with gdlearn. Many seeds rather than a few
long renders, because the standard error is estimated from the spread *between* seeds: with 32
seeds it has 31 degrees of freedom per pixel and stays honest for heavy-tailed estimates (caustics
seen through glass, light paths that rarely hit a small light), where 8 seeds underestimate it. The variant is ``scalar_rgb`` by default
because it works on every machine the ``mitsuba`` wheel installs on; ``llvm_ad_rgb`` (faster, needs
libLLVM >= 16) gives the same image up to noise and may be chosen with ``--variant``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # run from a clone without installing

from gdlearn.crosscheck import store  # noqa: E402
from gdlearn.crosscheck.mitsuba import import_mitsuba, mitsuba_mean_stderr, variant_works  # noqa: E402


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="*", help="case names (default: all); see --check for the list")
    p.add_argument("--spp", type=int, default=256, help="samples per pixel per seed (256)")
    p.add_argument("--seeds", type=int, default=32, help="number of independent seeds K (32)")
    p.add_argument("--variant", default="scalar_rgb", help="Mitsuba variant (scalar_rgb)")
    p.add_argument("--threads", type=int, default=None, help="Mitsuba threads (default: all cores)")
    p.add_argument("--check", action="store_true", help="only report missing or stale references")
    return p.parse_args(argv)


def check(cases) -> int:
    bad = 0
    for case in cases:
        try:
            _, s = store.load_reference(case)
            print(f"ok     {case.name:28s} {s['res']}x{s['res']}, {len(s['seeds'])} x {s['spp']} spp, "
                  f"{s['variant']}, Mitsuba {s['mitsuba_version']}")
        except (FileNotFoundError, ValueError) as err:
            bad += 1
            print(f"NEEDED {case.name:28s} {err}")
    return 1 if bad else 0


def main(argv=None) -> int:
    args = parse_args(argv)
    cases = store.reference_cases()
    if args.only:
        unknown = set(args.only) - {c.name for c in cases}
        if unknown:
            print(f"unknown case(s) {', '.join(sorted(unknown))}; known: "
                  f"{', '.join(c.name for c in cases)}", file=sys.stderr)
            return 2
        cases = [c for c in cases if c.name in args.only]
    if args.check:
        return check(cases)
    mi = import_mitsuba()
    if args.variant != "scalar_rgb":
        ok, why = variant_works(args.variant)
        if not ok:
            print(why, file=sys.stderr)
            return 2
    seeds = list(range(1000, 1000 + args.seeds))   # any fixed seeds; gdlearn's RNG is unrelated
    for case in cases:
        t0 = time.perf_counter()
        mean, se = mitsuba_mean_stderr(store.ROOT / case.scene, args.spp, seeds, args.variant,
                                       args.threads, res=store.RES, **case.mitsuba)
        dt = time.perf_counter() - t0
        settings = dict(res=store.RES, spp=args.spp, seeds=seeds, variant=args.variant,
                        mitsuba_version=mi.__version__, seconds=round(dt, 1))
        f = store.save_reference(case, mean, se, settings)
        lit = mean > 0
        rel = float((se[lit] / mean[lit]).mean()) if lit.any() else 0.0
        print(f"{case.name:28s} {dt:6.1f} s  mean RGB {mean.mean((0, 1)).round(4)}  "
              f"mean per-pixel stderr/mean {rel:.4f}  -> {f.relative_to(store.ROOT)} "
              f"({f.stat().st_size // 1024} KB)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
