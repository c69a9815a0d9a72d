"""G-BRE's cost per pass against the BRE's, light transport ending in the medium (Gruson et al. 2018
report G-BRE about 2x the BRE's time per iteration, Sec. 6.3).

Per scene and kernel (2D, 3D), JIT warmed, the passes of bre and gbre (3D: mixed shift; 2D: the
ray-frame copy; photon subsets on, as the paper's code) interleaved with bench_gvpm's timer, the
median time of a pass after the first, the ratio, the stage split and the photon-shift statistics.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gbre.py [--scenes scenes/fog-box.xml,...]
        [--kernels 3d,2d] [--res 64] [--photons 20000] [--repeats 3] [--threads 2]

``--kernel``: the camera pass alone, the fast kernel (gbre_gather.gbre_rows) against the one it
replaced (tests/_gbre_reference.py, which records tests/golden/passes/) on the same photons and radius
(pass 1 after pass 0), interleaved (old, new, old, ...) in one process, ``--repeats`` times per scene
and kernel (3D: mixed shift; 2D: the ray-frame copy; photon subsets on); prints the median and the
minimum of each, their ratio, whether the buffers are equal, and the load average before and after.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/bench_gbre.py --kernel --res 48 --photons 20000 \
        --repeats 5
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.bench_gvpm import SCENES, interleaved_times, old_vs_new, shift_line  # noqa: E402
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


def kernel_times(path, kernel, a) -> None:
    """Old and new camera pass on the same photons and radius, interleaved (module docstring)."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
    import _gbre_reference as ref
    from gdlearn.integrators.photon import gbre_gather as gb
    from gdlearn.integrators.photon import gvpm_gather as gg

    load0 = os.getloadavg()[0]
    g = make("gbre", load(path, res=a.res), seed=0, photons_per_pass=a.photons, threads=a.threads,
             transport="media", kernel=kernel)
    g.compile()
    g.render_pass(0)
    lp, bbhs, r, _ = g.build(g.trace_photons(1))
    kernels = {"old": lambda sa, lp, bbhs, *rest: ref.reference_rows(sa, lp, bbhs, *rest),
               "new": lambda sa, lp, bbhs, *rest: gb.gbre_rows(sa, lp, bbhs, g.mtab, *rest)}

    def call(rows, out):
        with g.setup.parallel(g.height):
            rows(g.setup.sa, lp, bbhs, float(r), g.gather_params, g.gp, g.wsub, g.seed, 2, out)

    line, _ = old_vs_new(kernels, call, lambda: gg.allocate(g.height, g.width), a.repeats)
    print(f"{os.path.basename(path):18s} {kernel} {line}  load average {load0:.2f} -> {os.getloadavg()[0]:.2f}",
          flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default=SCENES)
    p.add_argument("--kernels", default="3d,2d")
    p.add_argument("--res", type=int, default=64)
    p.add_argument("--photons", type=int, default=20_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--kernel", action="store_true", help="old vs new camera pass alone (module docstring)")
    a = p.parse_args(argv)
    for path in a.scenes.split(","):
        for kernel in a.kernels.split(","):
            (kernel_times if a.kernel else pass_times)(path, kernel, a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
