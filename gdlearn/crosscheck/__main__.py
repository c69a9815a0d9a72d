"""``python -m gdlearn.crosscheck``: differential tests of gdlearn against Mitsuba 3.

    python -m gdlearn.crosscheck fuzz --count 20                  # seeds 0..19 (see gdlearn.crosscheck.fuzz)
    python -m gdlearn.crosscheck fuzz --seed 7 --count 1          # one seed
    python -m gdlearn.crosscheck fuzz --count 20 --inject sigma_s*0.95   # must find failures
    python -m gdlearn.crosscheck check scene.xml                  # compare one scene file

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
    failed = 0
    for seed in range(a.seed, a.seed + a.count):
        v = fuzz.run_seed(seed, a.spp, a.variant, inject)
        print(f"seed {seed} (max_depth {v.max_depth}): {v.summary}", flush=True)
        if not v.ok:
            failed += 1
            xml = v.xml if a.no_shrink else fuzz.shrink(seed, a.spp, a.variant, inject)
            print(f"  minimal failing scene: {fuzz.write_failure(seed, xml, a.out, a.inject)}", flush=True)
    print(f"{a.count - failed}/{a.count} passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
