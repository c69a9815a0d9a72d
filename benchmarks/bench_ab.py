"""Two source trees of gdlearn side by side: time per pass and cold compile, interleaved.

For a change that must not alter speed (a refactoring), run the same configurations against the
tree before (``--a``, e.g. a ``git worktree`` of the parent commit) and after (``--b``). Each
measurement is a fresh process with ``PYTHONPATH`` pointing at one tree; the rounds alternate
A, B, A, B, ... so a change in the machine's load hits both alike. A process warms the JIT from
the tree's own numba cache (reported as ``warm compile``), then times ``--passes`` passes and
reports their median. With ``--cold`` each process starts from an empty cache instead (numba's
cold compile of that integrator on that scene).

    .venv/bin/python benchmarks/bench_ab.py --a /tmp/before --b . --rounds 3
    .venv/bin/python benchmarks/bench_ab.py --a /tmp/before --b . --rounds 1 --cold --integrators pt gpt

Prints one row per configuration: median of A, median of B, B / A, with the load average.
Nothing is asserted.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import gdlearn.scene as gs
from gdlearn.integrators import make
scene, integ_name, res, spp, passes = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
sc = gs.load(scene, res=res)
integ = make(integ_name, sc, seed=1, spp_per_pass=spp)
c0 = time.process_time()
c = integ.warmup()
c_cpu = time.process_time() - c0
ts = []
for i in range(passes):
    a = time.perf_counter()
    integ.render_pass(i)
    ts.append(time.perf_counter() - a)
ts.sort()
print(json.dumps({"compile": c, "compile_cpu": c_cpu, "pass": ts[len(ts) // 2], "start": time.perf_counter() - t0}))
"""


def run(tree: Path, args, scene: str, integ: str, cold: bool) -> dict:
    tree = tree.resolve()
    env = dict(os.environ, PYTHONPATH=str(tree))
    with tempfile.TemporaryDirectory() as cache:
        if cold:
            env["GDLEARN_CACHE"] = cache
            env.pop("NUMBA_CACHE_DIR", None)
        # cwd = the tree: ``python -c`` puts the working directory ahead of PYTHONPATH on sys.path, so
        # run from a checkout, both sides would import that checkout's gdlearn
        out = subprocess.run([sys.executable, "-c", CHILD, str(tree / "scenes" / f"{scene}.xml"), integ, str(args.res),
                              str(args.spp), str(args.passes)], env=env, capture_output=True, text=True, check=True,
                             cwd=str(tree))
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--a", type=Path, required=True, help="the tree before")
    ap.add_argument("--b", type=Path, required=True, help="the tree after")
    ap.add_argument("--scenes", nargs="+", default=["cornell-box", "fog-box", "caustics-box", "mesh"])
    ap.add_argument("--integrators", nargs="+", default=["pt", "gpt-replay", "gpt"])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--cold", action="store_true", help="empty numba cache in every process (cold compile)")
    a = ap.parse_args(argv)
    key = "compile" if a.cold else "pass"
    print(f"# A = {a.a.resolve()}\n# B = {a.b.resolve()}\n# {a.res}^2, {a.spp} spp per pass, median of {a.passes} "
          f"passes, {a.rounds} rounds A/B interleaved; {'cold compile' if a.cold else 'seconds per pass'}; "
          f"load average before {os.getloadavg()[0]:.2f}")
    print(f"{'scene':14s} {'integrator':11s} {'A':>9s} {'B':>9s} {'B/A':>6s}")
    for scene in a.scenes:
        for integ in a.integrators:
            ra, rb = [], []
            for _ in range(a.rounds):
                ra.append(run(a.a, a, scene, integ, a.cold))
                rb.append(run(a.b, a, scene, integ, a.cold))
            ma, mb = (statistics.median(r[key] for r in rs) for rs in (ra, rb))
            cpu = ""
            if a.cold:      # the CPU seconds of the compile: less sensitive to other jobs on the machine
                ca, cb = (statistics.median(r["compile_cpu"] for r in rs) for rs in (ra, rb))
                cpu = f"   CPU s {ca:7.1f} {cb:7.1f} {cb / ca:6.3f}"
            print(f"{scene:14s} {integ:11s} {ma:9.4f} {mb:9.4f} {mb / ma:6.3f}{cpu}   load {os.getloadavg()[0]:.2f}",
                  flush=True)
    print(f"# load average after {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
