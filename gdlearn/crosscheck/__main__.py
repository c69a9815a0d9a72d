"""``python -m gdlearn.crosscheck``: differential tests of gdlearn against Mitsuba 3.

    python -m gdlearn.crosscheck fuzz --count 20                  # seeds 0..19 (see gdlearn.crosscheck.fuzz)
    python -m gdlearn.crosscheck fuzz --seed 7 --count 1          # one seed
    python -m gdlearn.crosscheck fuzz --count 20 --inject sigma_s*0.95   # must find failures
    python -m gdlearn.crosscheck check scene.xml                  # compare one scene file
    python -m gdlearn.crosscheck fuzz --count 20 --gradients gpt,gpt-replay   # gradients too

A failing seed is shrunk to a minimal scene that still fails, written to ``--out`` (default
``fuzz-failures/``) with the command that reproduces it. Exit status: 0 all passed, 1 some failed.
"""
from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    from gdlearn.crosscheck import fuzz

    p = argparse.ArgumentParser(prog="python -m gdlearn.crosscheck", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fuzz", help="random scenes, gdlearn pt against Mitsuba 3")
    f.add_argument("--count", type=int, default=10)
    f.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    f.add_argument("--spp", type=int, default=64, help="gdlearn spp per batch (Mitsuba: twice that)")
    f.add_argument("--variant", default="scalar_rgb")
    f.add_argument("--inject", choices=sorted(fuzz.INJECTIONS), default=None,
                   help="a deliberate bias in gdlearn's copy of the scene (the fuzzer must catch it)")
    f.add_argument("--out", default="fuzz-failures", help="folder for minimal failing scenes")
    f.add_argument("--no-shrink", action="store_true")
    f.add_argument("--gradients", default="", metavar="gpt,gpt-replay",
                   help="also check these gradient integrators on each scene (mean gradient against "
                        "the finite differences of the primal; 32 renders of 8 spp each)")
    f.add_argument("--no-images", action="store_true", help="skip the image comparison (gradients only)")
    c = sub.add_parser("check", help="compare one scene file")
    c.add_argument("scene")
    c.add_argument("--spp", type=int, default=64)
    c.add_argument("--variant", default="scalar_rgb")
    a = p.parse_args(argv)
    if a.cmd == "check":
        with open(a.scene) as fh:
            cmp = fuzz.check_xml(fh.read(), a.spp, a.variant)
        print(cmp.summary())
        return 0 if cmp.ok else 1
    inject = fuzz.INJECTIONS[a.inject] if a.inject else None
    failed = unsure = 0
    grads = [g for g in a.gradients.split(",") if g]
    g_failed = 0
    for seed in range(a.seed, a.seed + a.count):
        if not a.no_images:
            v = fuzz.run_seed(seed, a.spp, a.variant, inject)
            print(f"seed {seed} (max_depth {v.max_depth}): {v.summary}", flush=True)
            if v.inconclusive:
                unsure += 1
            elif not v.ok:
                failed += 1
                xml = v.xml if a.no_shrink else fuzz.shrink(seed, a.spp, a.variant, inject)
                print(f"  minimal failing scene: {fuzz.write_failure(seed, xml, a.out, a.inject)}", flush=True)
        for g in grads:
            chk, xml = fuzz.run_gradient_seed(seed, g)
            print(f"seed {seed} {g} gradients: {chk.summary()}", flush=True)
            if not chk.ok:
                g_failed += 1
                print(f"  scene: {fuzz.write_failure(seed, xml, a.out)}", flush=True)
    if not a.no_images:
        print(f"{a.count - failed - unsure}/{a.count} passed, {failed} failed, {unsure} inconclusive "
              f"(image mean unresolved at {fuzz.MAX_RETRIES} retries with 4x the samples)")
    if grads:
        print(f"gradients: {a.count * len(grads) - g_failed}/{a.count * len(grads)} passed ({', '.join(grads)})")
    return 1 if failed or g_failed else 0


if __name__ == "__main__":
    sys.exit(main())
