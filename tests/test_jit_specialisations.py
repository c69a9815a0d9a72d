"""Each compiled function is compiled once per real argument type (kernels.jit).

numba would otherwise compile a callee once per constant passed at a call site (a Literal type) and
once more for every non-inlined callee of a ``prange`` loop that receives the row index (int64 while
typing, uint64 while lowering): a third of gpt's cold compile went to such copies. After pt and the
default gpt render the Cornell box, no gdlearn dispatcher may hold two signatures that differ only
in those ways; and the default gpt kernel has no manifold code (mtab None). A planted copy (the
same function called with a literal) must be reported, so the check cannot pass by seeing nothing.
"""
import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from numba.core import types
from numba.core.dispatcher import Dispatcher

from gdlearn.integrators import make
from gdlearn.integrators.path.gpt import _gpt_rows
from gdlearn.integrators.path.gpt_surface.manifold import lookahead_chain, manifold_offset
from gdlearn.kernels.jit import block
from gdlearn.scene.load import load

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def _normal(t):
    t = types.unliteral(t)
    if isinstance(t, types.Integer) and not t.signed and t.bitwidth == 64:
        return types.int64
    return t


def _copies(only_gdlearn=True):
    """Dispatchers with two signatures equal up to literals and the row index's signedness."""
    out = []
    for d in gc.get_objects():
        # type(), not isinstance(): Dispatcher is an ABC, whose isinstance consults the object's
        # __class__, which some live objects answer by raising (seen once after another test's np.load)
        if not issubclass(type(d), Dispatcher) or (only_gdlearn and not d.py_func.__module__.startswith("gdlearn")):
            continue
        seen = {}
        for sig in d.signatures:
            key = tuple(str(_normal(a)) for a in sig)
            if key in seen:
                out.append((d.py_func.__qualname__, seen[key], sig))
            seen[key] = sig
    return out


def _compile_and_report():
    """Run in a fresh process with an empty numba cache (a cached kernel loads without typing its
    callees, so a warm cache would show no copies at all): compile pt and the default gpt."""
    scene = load(SCENES / "cornell-box.xml", res=8)
    for name in ("pt", "gpt"):
        integ = make(name, scene, seed=0, spp_per_pass=1, threads=1)
        integ.warmup()
    print(json.dumps({"copies": [str(c[0]) for c in _copies()], "manifold": integ.manifold,
                      "mtab": sorted({str(sig[8]) for sig in _gpt_rows.signatures}),
                      "walk": len(lookahead_chain.signatures) + len(manifold_offset.signatures)}))


def test_pt_and_gpt_compile_each_function_once_per_type(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), PYTHONPATH=str(SCENES.parent))
    r = subprocess.run([sys.executable, __file__], env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    rep = json.loads(r.stdout.strip().splitlines()[-1])
    assert rep["copies"] == []
    # the default gpt kernel on the Cornell box types its rows (and gpt_sample, IR-inlined into them)
    # for mtab None only: no manifold code, the walk's functions never typed
    assert not rep["manifold"] and rep["mtab"] == ["none"] and rep["walk"] == 0


def _planted_callee(a, k):
    return a[k]


def test_a_planted_literal_copy_is_reported():
    from numba import njit

    callee = njit(_planted_callee)            # numba's own dispatcher: one copy per literal

    @njit
    def caller(a):
        return callee(a, 0) + callee(a, 1)

    caller(np.ones(2))
    assert any(q == "_planted_callee" for q, _, _ in _copies(only_gdlearn=False))
    ours = block(_planted_callee)

    @njit
    def caller2(a):
        return ours(a, 0) + ours(a, 1)

    caller2(np.ones(2))
    assert len(ours.signatures) == 1


if __name__ == "__main__":
    _compile_and_report()
