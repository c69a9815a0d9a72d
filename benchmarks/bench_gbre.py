"""G-BRE's cost per pass against the BRE's, light transport ending in the medium (Gruson et al. 2018
report G-BRE about 2x the BRE's time per iteration, Sec. 6.3).

Per scene and kernel (2D, 3D), JIT warmed, the passes of bre and gbre (3D: mixed shift; 2D: the
ray-frame copy; photon subsets on, as the paper's code) interleaved with bench_gvpm's timer, the
median time of a pass after the first, the ratio, the stage split and the photon-shift statistics.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gbre.py [--scenes scenes/fog-box.xml,...]
        [--kernels 3d,2d] [--res 64] [--photons 20000] [--repeats 3] [--threads 2]
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.bench_gvpm import SCENES, interleaved_times, shift_line  # noqa: E402
from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402


def pass_times(path, kernel, a) -> None:
    scene = load(path, res=a.res)
    common = dict(seed=0, photons_per_pass=a.photons, threads=a.threads, transport="media", kernel=kernel)
    integs = {"bre": make("bre", scene, **common), "gbre": make("gbre", scene, **common),
              "gbre-nosubsets": make("gbre", scene, subsets=False, **common)}
    med, last = interleaved_times(integs, a.repeats)
    line = f"{os.path.basename(path):18s} {kernel} " + "  ".join(f"{n} {t:6.3f} s/pass" for n, t in med.items())
    line += f"  gbre/bre {med['gbre'] / med['bre']:5.2f}  no-subsets/bre {med['gbre-nosubsets'] / med['bre']:5.2f}"
    print(line, flush=True)
    for n in ("gbre", "gbre-nosubsets"):
        print(shift_line(n, last[n]), flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=SCENES)
    p.add_argument("--kernels", default="3d,2d")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--photons", type=int, default=20_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args(argv)
    for path in a.scenes.split(","):
        for kernel in a.kernels.split(","):
            pass_times(path, kernel, a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
