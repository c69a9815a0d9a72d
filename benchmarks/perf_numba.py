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
passes). ``--lines`` compiles with debug info (``NUMBA_DEBUGINFO``: the same optimised code, line
tables added) and also ranks source lines, each sample's innermost line (after inlining: where the
instruction came from) and the line of the outermost function it was inlined into (which call of
the kernel's body led there); ``addr2line -i`` reads them from each library's object code. A
sample lands on the instruction that waits, so a line's share is where time is spent, not always
what causes it. benchmarks/README.md, "Photon subsets at equal time, and where G-BRE's walks spend".
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
import warnings
from collections import defaultdict


def _value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"True": True, "False": False}.get(text, text)


def _symbols(lib, keep: str | None = None) -> tuple[list[tuple[int, int, str]], int]:
    """(address, size, name) of the functions in one compiled numba library ([] if it has no object
    code) and the library's base (a symbol's runtime address less its value in the object file).
    ``keep``: a path to leave the object file at (for :func:`line_report`)."""
    try:
        obj = lib._get_compiled_object()
    except (RuntimeError, ValueError):      # from numba's cache, or a library that keeps no object code
        return [], 0
    with tempfile.NamedTemporaryFile(suffix=".o") as f:
        f.write(obj)
        f.flush()
        out = subprocess.run(["nm", "-S", "--defined-only", f.name], capture_output=True, text=True).stdout
        if keep:
            shutil.copyfile(f.name, keep)
    rows = [ln.split() for ln in out.splitlines()]
    syms = [(int(a, 16), int(s, 16), n) for a, s, t, n in (r for r in rows if len(r) == 4) if t in "tT"]
    for off, _, name in syms:               # the library's base: one symbol the engine can resolve
        try:
            addr = lib.get_pointer_to_function(name)
        except Exception:                   # noqa: BLE001 -- any symbol the engine refuses is skipped
            addr = 0
        if addr:
            return [(addr - off + o, size, n) for o, size, n in syms], addr - off
    return [], 0


def write_perf_map(pid: int, objdir: str | None = None) -> tuple[int, list]:
    """/tmp/perf-<pid>.map from every live numba dispatcher's compiled libraries (module functions and
    the ones factories build as closures); returns the symbols written and, with ``objdir``, each
    library's (start, end, object file, base) -- its code's runtime range, its object code kept
    there, and the base that maps a runtime address to the object file's (one code section)."""
    from numba.core.registry import CPUDispatcher
    lines, seen, libs = [], set(), []
    todo = [cres.library for o in gc.get_objects() if isinstance(o, CPUDispatcher) for cres in o.overloads.values()]
    while todo:                             # and the libraries they link (a parallel kernel's gufunc, ...)
        lib = todo.pop()
        if id(lib) in seen:
            continue
        seen.add(id(lib))
        keep = os.path.join(objdir, f"{len(seen)}.o") if objdir else None
        syms, base = _symbols(lib, keep)
        lines += [f"{a:x} {s:x} {n}" for a, s, n in syms]
        if keep and syms:
            libs.append((min(a for a, _, _ in syms), max(a + s for a, s, _ in syms), keep, base))
        todo += list(getattr(lib, "_linking_libraries", ()))
    with open(f"/tmp/perf-{pid}.map", "w") as f:
        f.write("\n".join(lines) + "\n")
    return len(lines), libs


def line_report(data: str, libs: list, top: int) -> None:
    """The samples per source line (the object code's debug info, ``addr2line -i``): the innermost
    line (where the instruction came from, after inlining) and the line of the outermost function
    (the statement of the numba function perf names) that led to it."""
    ips = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True, text=True).stdout.split()
    per_lib = defaultdict(lambda: defaultdict(int))
    total = 0
    for ip in ips:
        a = int(ip, 16)
        total += 1
        for start, end, obj, base in libs:
            if start <= a < end:
                per_lib[obj][a - base] += 1
                break
    inner, outer = defaultdict(int), defaultdict(int)
    for obj, offs in per_lib.items():
        keys = sorted(offs)
        out = subprocess.run(["addr2line", "-e", obj, "-i", "-a"] + [hex(k) for k in keys],
                             capture_output=True, text=True).stdout
        frames = defaultdict(list)
        cur = None
        for ln in out.splitlines():
            if ln.startswith("0x"):
                cur = int(ln, 16)
            else:
                frames[cur].append(_shorter(ln))
        for k in keys:
            fr = frames.get(k) or ["??"]
            inner[fr[0]] += offs[k]
            outer[fr[-1]] += offs[k]
    for title, table in (("innermost source line", inner), ("outermost function's line", outer)):
        print(f"\n{title} (share of all {total} samples)")
        for name, n in sorted(table.items(), key=lambda kv: -kv[1])[:top]:
            print(f"{100.0 * n / total:6.2f} %  {name}")


def _shorter(loc: str) -> str:
    """``/.../gdlearn/kernels/bvh.py:12 (discriminator 3)`` -> ``kernels/bvh.py:12``."""
    loc = loc.split(" (")[0]
    return loc.split("/gdlearn/", 1)[-1] if "/gdlearn/" in loc else loc


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
    p.add_argument("--lines", action="store_true",
                   help="compile with debug info (NUMBA_DEBUGINFO) and report the samples per source line too")
    a = p.parse_args(argv)
    for tool in ("perf", "nm") + (("addr2line",) if a.lines else ()):
        if shutil.which(tool) is None:
            raise SystemExit(f"perf_numba: {tool} not found; fix: install it (linux-perf / binutils)")
    bad = [kv for kv in a.option if "=" not in kv]
    if bad:
        raise SystemExit(f"perf_numba: --option {bad[0]!r}; fix: KEY=VALUE, e.g. --option transport=media")
    opts = {k: _value(v) for k, v in (kv.split("=", 1) for kv in a.option)}
    # before numba is imported: an empty cache, so every library is compiled here and keeps its object code
    cache = tempfile.mkdtemp(prefix="perf_numba_")
    os.environ["NUMBA_CACHE_DIR"] = cache
    if a.lines:
        os.environ["NUMBA_DEBUGINFO"] = "1"
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
    from numba.core.errors import NumbaDebugInfoWarning
    # numba's own lambdas (array reprs) have no source file: their lines are not ours to rank
    warnings.filterwarnings("ignore", category=NumbaDebugInfoWarning)
    from gdlearn.integrators import make
    from gdlearn.scene.load import load
    integ = make(a.integrator, load(a.scene, res=a.res), seed=0, threads=a.threads, **opts)
    t0 = time.perf_counter()
    integ.compile()
    integ.render_pass(0)
    n, libs = write_perf_map(os.getpid(), cache if a.lines else None)
    print(f"compiled and warmed in {time.perf_counter() - t0:.0f} s; {n} symbols mapped")
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
    if a.lines:
        line_report(data, libs, a.top)


if __name__ == "__main__":
    sys.exit(main())
