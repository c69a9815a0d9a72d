#!/usr/bin/env python
"""Where a cold compile goes: each numba function's own compile time and its LLVM share.

    .venv/bin/python benchmarks/compile_profile.py --scene caustic-closeup --integrator gpt [--top 25]

Compiles the integrator's kernels (``compile()`` at ``--res``, one thread) in this process with an
empty numba cache of its own, so that everything is compiled, and records numba's ``numba:compile``
and ``numba:llvm_lock`` events. A function's *own* time is its compile's duration less the compiles
nested in it (its callees, compiled on first call); its LLVM time is the LLVM work under it that no
nested compile claimed. A caller's LLVM time includes optimising and emitting again every callee it
links in, which is why one-caller functions are IR-inlined into their row drivers
(:mod:`gdlearn.kernels.jit`; benchmarks/README.md, "Compiled once"). Run it alone: a compile's time
moves with everything else on the machine. To compare two trees, run each tree's copy alternately.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


class _Recorder:
    """numba event listener (registered as a ``Listener`` subclass, :func:`_listener`): a stack of
    open compiles, each with its nested compile and LLVM time."""

    def __init__(self):
        self.open, self.rows = [], []

    def on_start(self, event):
        self.open.append([event.kind, time.perf_counter(), 0.0, 0.0])

    def on_end(self, event):
        kind, t0, nested, llvm = self.open.pop()
        dt = time.perf_counter() - t0
        if kind == "numba:compile":
            fn = getattr(event.data.get("dispatcher"), "py_func", None)
            name = f"{fn.__module__}.{fn.__qualname__}" if fn else str(event.data)[:70]
            self.rows.append((dt - nested, llvm, name))
            if self.open:
                self.open[-1][2] += dt
            return
        if any(frame[0] == kind for frame in self.open):
            return                               # a re-entered LLVM lock: its outermost holder counts it
        for frame in reversed(self.open):        # LLVM time goes to the innermost open compile
            if frame[0] == "numba:compile":
                frame[3] += dt
                break


def _listener():
    from numba.core.event import Listener       # numba is imported only once its cache folder is set

    class Recorder(_Recorder, Listener):
        pass

    return Recorder()


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cornell-box", help="scenes/<name>.xml")
    p.add_argument("--integrator", default="gpt")
    p.add_argument("--res", type=int, default=16)
    p.add_argument("--top", type=int, default=25, help="functions listed, largest own time first")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="gdlearn-compile-") as cache:
        os.environ["NUMBA_CACHE_DIR"] = cache          # before numba loads: an empty cache
        profile(a)


def profile(a):
    from numba.core import event

    from gdlearn.integrators import make
    from gdlearn.scene import load

    integ = make(a.integrator, load(ROOT / "scenes" / f"{a.scene}.xml", res=a.res), spp_per_pass=1, threads=1)
    rec = _listener()
    event.register("numba:compile", rec)
    event.register("numba:llvm_lock", rec)
    t0 = time.perf_counter()
    integ.compile()
    total = time.perf_counter() - t0
    rows = sorted(rec.rows, reverse=True)
    llvm = sum(r[1] for r in rows)
    print(f"# {a.integrator} on {a.scene}: compile() {total:.1f} s, {len(rows)} functions compiled, "
          f"LLVM {llvm:.1f} s ({100 * llvm / max(total, 1e-9):.0f} %)")
    print(f"{'own s':>7s} {'LLVM s':>7s}  function")
    for own, ll, name in rows[:a.top]:
        print(f"{own:7.2f} {ll:7.2f}  {name}")


if __name__ == "__main__":
    main()
