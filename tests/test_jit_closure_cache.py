"""Kernels made by a factory -- a compiled closure over compiled functions, as
``gpm_gather.threaded_rows`` and ``photon_shift_loop.make_shift_photons`` make them -- are found in
numba's on-disk cache by the next process (``kernels.jit._ClosureCache``), keep apart when they close
over different functions, and are compiled anew when a function they close over is edited.

numba's own key pickles the closure's cells, and a compiled function pickles with a uuid drawn per
process: with ``FunctionCache`` in ``kernels.jit._compile`` (numba's ``enable_caching``) the second
process below misses the cache for both closures, and the first and third tests fail (checked by
hand). Keying a compiled cell by its name alone (no bytecode or file stamp) fails the third: the
edited function's closure is loaded stale and returns 7 instead of 10.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

FUNCS = '''
from gdlearn.kernels.jit import block


@block
def double(x):
    return {factor} * x
'''

SQUARE = '''
from gdlearn.kernels.jit import block


@block
def square(x):
    return x * x
'''

FACTORY = '''
from gdlearn.kernels.jit import block


def make_apply(f):
    @block
    def apply(x):
        return f(x) + 1.0
    return apply
'''

MAIN = '''
import json
from factory import make_apply
from funcs import double
from square import square

a, b = make_apply(double), make_apply(square)
out = {"double": a(3.0), "square": b(3.0)}
for name, d in (("double", a), ("square", b)):
    out[name + "_hits"] = sum(d.stats.cache_hits.values())
    out[name + "_misses"] = sum(d.stats.cache_misses.values())
print(json.dumps(out))
'''


def _write(folder: Path, factor: str):
    (folder / "funcs.py").write_text(FUNCS.format(factor=factor))
    (folder / "square.py").write_text(SQUARE)
    (folder / "factory.py").write_text(FACTORY)
    (folder / "main.py").write_text(MAIN)


def _run(folder: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(folder / "cache"))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(folder), str(ROOT), env.get("PYTHONPATH")]))
    res = subprocess.run([sys.executable, str(folder / "main.py")], cwd=folder, env=env, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_a_new_process_loads_a_closure_from_the_cache(tmp_path):
    _write(tmp_path, "2.0")
    first = _run(tmp_path)
    assert first["double_misses"] == 1 and first["square_misses"] == 1
    second = _run(tmp_path)
    assert (second["double_hits"], second["double_misses"]) == (1, 0)
    assert (second["square_hits"], second["square_misses"]) == (1, 0)


def test_closures_over_different_functions_keep_apart(tmp_path):
    _write(tmp_path, "2.0")
    for _ in range(2):                           # compiled, then both loaded from one index file
        out = _run(tmp_path)
        assert (out["double"], out["square"]) == (7.0, 10.0)


def test_an_edited_function_recompiles_the_closure_over_it(tmp_path):
    _write(tmp_path, "2.0")
    assert _run(tmp_path)["double"] == 7.0
    # the factory's file is untouched: only the captured function's bytecode and file stamp change,
    # and the closure over the function of another file is still found
    (tmp_path / "funcs.py").write_text(FUNCS.format(factor="3.0"))
    out = _run(tmp_path)
    assert out["double"] == 10.0 and out["double_misses"] == 1
    assert out["square_hits"] == 1 and out["square_misses"] == 0
