"""G-VPM's cost per pass against VPM's, light transport ending in the medium (Gruson et al. 2018 report
G-VPM about 1.3x VPM's time per iteration, Sec. 6.3).

Per scene, JIT warmed, the passes of vpm, gvpm (mixed shift) and gvpm (simple shift) *interleaved*
(vpm, gvpm, gvpm-simple, vpm, ...; all see the same load), the median time of a pass of each after
the first (which also measures the initial radii), their ratios, the stage split, and the photon-shift
statistics (null / mixed / reconnected / failed, per gathered photon and neighbour).

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gvpm.py [--scenes scenes/fog-box.xml,...]
        [--res 128] [--photons 100000] [--repeats 3] [--threads 2]
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

SCENES = "scenes/fog-box.xml,scenes/spot-medium.xml"
KINDS = ("null", "mixed", "reconnected", "failed")


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


def shift_line(name: str, res) -> str:
    """The stage split and photon-shift statistics of a gradient pass (per gathered photon and neighbour)."""
    st = res.stats
    c = {k: st[f"photon_shifts_{k}"] for k in KINDS}
    tot = max(c["null"] + c["reconnected"] + c["failed"], 1)
    stage = {k: res.timings.get(k, 0.0) for k in ("photons", "build", "gather")}
    return (f"    {name:12s} stages: light paths {stage['photons']:.3f} s, build {stage['build']:.3f} s, gather "
            f"{stage['gather']:.3f} s; photon shifts: null {c['null'] / tot:.1%}, reconnected "
            f"{c['reconnected'] / tot:.1%} (of which reflected by Eq. 16 {c['mixed'] / tot:.1%}), failed "
            f"{c['failed'] / tot:.1%}; gathered photons {st['volume_photons_gathered']}")


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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=SCENES)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--photons", type=int, default=100_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args(argv)
    for path in a.scenes.split(","):
        pass_times(path, a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
