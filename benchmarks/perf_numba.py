"""Where a gdlearn pass spends its time: ``perf record`` with a perf map of every numba library.

perf sees numba's machine code as anonymous JIT memory. This script compiles the integrator in-process
(an empty ``NUMBA_CACHE_DIR``: a library loaded from numba's cache keeps no object code to read),
then writes ``/tmp/perf-<pid>.map`` from every compiled library of every live numba dispatcher --
each symbol's offset and size from ``nm -S`` of the library's object code, the library's base from
one symbol's address -- and records the timed passes only (``perf record -p``, the JIT
warmed). An IR-inlined camera pass calls into its callees' own libraries, so the entry points of
the dispatchers alone would leave most samples unnamed. Prints the share of the samples per
function, a function's specialisations summed.

    flock /tmp/gdlearn-bench.lock .venv/bin/python benchmarks/perf_numba.py --scene scenes/volume-caustic.xml \\
        --integrator gbre --res 128 --passes 24 --threads 1 --option photons_per_pass=100000 --option transport=media

Needs ``perf`` (software sampling is enough: no hardware counters on this machine) and ``nm``.
One thread gives the cleanest shares; the first run compiles everything (minutes for the photon
passes). benchmarks/README.md, "Photon subsets at equal time, and where G-BRE's walks spend".
"""
from __future__ import annotations

import argparse
import contextlib
import gc
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict


def _value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"True": True, "False": False}.get(text, text)


def _symbols(lib) -> list[tuple[int, int, str]]:
    """(address, size, name) of the functions in one compiled numba library, [] if it has no object code."""
    try:
        obj = lib._get_compiled_object()
    except (RuntimeError, ValueError):      # from numba's cache, or a library that keeps no object code
        return []
    with tempfile.NamedTemporaryFile(suffix=".o") as f:
        f.write(obj)
        f.flush()
        out = subprocess.run(["nm", "-S", "--defined-only", f.name], capture_output=True, text=True).stdout
    rows = [ln.split() for ln in out.splitlines()]
    syms = [(int(a, 16), int(s, 16), n) for a, s, t, n in (r for r in rows if len(r) == 4) if t in "tT"]
    for off, _, name in syms:               # the library's base: one symbol the engine can resolve
        try:
            addr = lib.get_pointer_to_function(name)
        except Exception:                   # noqa: BLE001 -- any symbol the engine refuses is skipped
            addr = 0
        if addr:
            return [(addr - off + o, size, n) for o, size, n in syms]
    return []


def write_perf_map(pid: int) -> int:
    """/tmp/perf-<pid>.map from every live numba dispatcher's compiled libraries (module functions and
    the ones factories build as closures); returns the symbols written."""
    from numba.core.registry import CPUDispatcher
    lines, seen = [], set()
    todo = [cres.library for o in gc.get_objects() if isinstance(o, CPUDispatcher) for cres in o.overloads.values()]
    while todo:                             # and the libraries they link (a parallel kernel's gufunc, ...)
        lib = todo.pop()
        if id(lib) in seen:
            continue
        seen.add(id(lib))
        lines += [f"{a:x} {s:x} {n}" for a, s, n in _symbols(lib)]
        todo += list(getattr(lib, "_linking_libraries", ()))
    with open(f"/tmp/perf-{pid}.map", "w") as f:
        f.write("\n".join(lines) + "\n")
    return len(lines)


def _short(symbol: str) -> str:
    """A numba symbol's module.function, without its specialisation: the Itanium-mangled nested name
    (length-prefixed parts after ``_ZN``) up to numba's ABI tags (``B``...)."""
    if symbol.startswith("0x"):
        return "[unmapped JIT code]"       # outside every mapped library (numba's helpers, ...)
    body = symbol.removeprefix("cfunc.")
    if not body.startswith("_ZN"):
        return symbol
    i, names = 3, []
    while i < len(body) and body[i].isdigit():
        j = i
        while j < len(body) and body[j].isdigit():
            j += 1
        n = int(body[i:j])
        names.append(body[j:j + n])
        i = j + n
    names = [n for n in names if n != "cpython"]
    return ".".join(names) if names else symbol


def report(data: str, top: int) -> None:
    out = subprocess.run(["perf", "report", "-i", data, "--no-children", "--sort", "symbol", "--stdio"],
                         capture_output=True, text=True).stdout
    share = defaultdict(float)
    for ln in out.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+\[[.k]\]\s+(\S+)", ln)
        if m:
            share[_short(m.group(2))] += float(m.group(1))
    for name, pct in sorted(share.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{pct:6.2f} %  {name}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="scenes/volume-caustic.xml")
    p.add_argument("--integrator", default="gbre")
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--passes", type=int, default=24)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE", help="make()'s options")
    p.add_argument("--top", type=int, default=30)
    a = p.parse_args(argv)
    for tool in ("perf", "nm"):
        if shutil.which(tool) is None:
            raise SystemExit(f"perf_numba: {tool} not found; fix: install it (linux-perf / binutils)")
    bad = [kv for kv in a.option if "=" not in kv]
    if bad:
        raise SystemExit(f"perf_numba: --option {bad[0]!r}; fix: KEY=VALUE, e.g. --option transport=media")
    opts = {k: _value(v) for k, v in (kv.split("=", 1) for kv in a.option)}
    # before numba is imported: an empty cache, so every library is compiled here and keeps its object code
    cache = tempfile.mkdtemp(prefix="perf_numba_")
    os.environ["NUMBA_CACHE_DIR"] = cache
    try:
        profile(a, opts, cache)
    finally:                                # nothing of the run is kept: its compiled cache, perf.data, map
        shutil.rmtree(cache, ignore_errors=True)
        with contextlib.suppress(FileNotFoundError):
            os.remove(f"/tmp/perf-{os.getpid()}.map")
    return 0


def profile(a, opts: dict, cache: str) -> None:
    """Compile and warm ``a.integrator``, map its libraries, record ``a.passes`` passes, print the shares."""
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
    from gdlearn.integrators import make
    from gdlearn.scene.load import load
    integ = make(a.integrator, load(a.scene, res=a.res), seed=0, threads=a.threads, **opts)
    t0 = time.perf_counter()
    integ.compile()
    integ.render_pass(0)
    print(f"compiled and warmed in {time.perf_counter() - t0:.0f} s; {write_perf_map(os.getpid())} symbols mapped")
    data = os.path.join(cache, "perf.data")
    rec = subprocess.Popen(["perf", "record", "-F", "2999", "-p", str(os.getpid()), "-o", data],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)                         # perf attaches
    t0 = time.perf_counter()
    for i in range(1, a.passes + 1):
        integ.render_pass(i)
    print(f"{a.passes} passes in {time.perf_counter() - t0:.2f} s, load {os.getloadavg()[0]:.2f}")
    rec.send_signal(2)
    rec.wait()
    report(data, a.top)


if __name__ == "__main__":
    sys.exit(main())
