"""Light-path records (gdlearn.photons): deterministic under the light-path key space, consistent
links and pdfs, and the emitted power of the emitter sampling."""
import math
from pathlib import Path

import numba
import numpy as np
import pytest

import gdlearn.scene
from gdlearn.photons.emit import emitter_power
from gdlearn.photons.records import F_PHOTON, K_EMITTER, K_SURFACE
from gdlearn.photons.trace import LightTracer, TraceParams
from gdlearn.scene.compile import compile_scene

ROOT = Path(__file__).resolve().parent.parent
PARAMS = TraceParams(7, 5, 0.05, True, True)


@pytest.fixture(scope="module")
def cornell():
    return compile_scene(gdlearn.scene.load(str(ROOT / "scenes/cornell-box.xml"), res=8))


def _trace(sa, threads, n=3000, seed=5, pass_index=2, j0=0, batch=1024):
    return LightTracer(sa, PARAMS, batch=batch, threads=threads).trace(seed, pass_index, j0, n)


def test_same_records_for_one_and_two_threads_and_any_batch(cornell):
    a = _trace(cornell, 1)
    b = _trace(cornell, min(2, numba.config.NUMBA_NUM_THREADS), batch=4096)
    for name, x, y in zip(a._fields, a, b):
        assert np.array_equal(x, y), name
    # a pure function of (seed, pass, j): paths 1000..2999 traced alone are the same rows
    c = _trace(cornell, 1, n=2000, j0=1000)
    first = np.flatnonzero(a.path >= 1000)[0]
    assert np.array_equal(a.pos[first:], c.pos) and np.array_equal(a.path[first:], c.path)
    d = _trace(cornell, 1, seed=6)
    assert not np.array_equal(a.pos[:100], d.pos[:100])


def test_record_links_kinds_and_photons(cornell):
    lp = _trace(cornell, None)
    root = lp.depth == 0
    assert (lp.kind[root] == K_EMITTER).all() and (lp.parent[root] == -1).all()
    child = ~root
    assert (lp.kind[child] == K_SURFACE).all()
    assert np.array_equal(lp.parent[child], np.flatnonzero(child) - 1)
    assert np.array_equal(lp.depth[child], lp.depth[lp.parent[child]] + 1)
    assert (lp.path[child] == lp.path[lp.parent[child]]).all()
    # photons: surface vertices only (never the emitter vertex); every Cornell material is diffuse
    ph = lp.photons
    assert ph.size == child.sum() and (lp.depth[ph] >= 1).all() and (lp.flags[ph] & F_PHOTON).all()
    # the edge into a vertex points from its parent to it
    e = lp.pos[child] - lp.pos[lp.parent[child]]
    e /= np.linalg.norm(e, axis=1)[:, None]
    np.testing.assert_allclose(np.einsum("ij,ij->i", e, lp.d_in[child]), 1.0, atol=1e-9)
    # diffuse vertices: the area pdf is cos / pi * cos' / d^2 from the parent's sample
    assert (lp.pdf_fwd[child] > 0).all() and np.isfinite(lp.beta).all()


def test_emitted_power_is_the_emitters_power(cornell):
    """E[vertex-0 weight] = the total emitted power pi A Le; 4 standard errors (the weight of one
    area light is constant, so the check is exact up to rounding)."""
    lp = LightTracer(cornell, PARAMS._replace(keep_escaped=True)).trace(5, 2, 0, 2000)
    w = lp.beta[lp.depth == 0].mean(axis=1)
    assert w.size == 2000
    total = emitter_power(cornell).sum()
    assert abs(w.mean() - total) <= 4 * w.std() / math.sqrt(w.size) + 1e-9 * total


def test_point_light_power_and_direction_sampling():
    sa = compile_scene(gdlearn.scene.load(str(ROOT / "tests/scenes_photons/plane-point.xml")))
    lp = LightTracer(sa, TraceParams(1, 5, 0.05, True, True, keep_escaped=True)).trace(0, 0, 0, 20000)
    v0 = lp.depth == 0
    np.testing.assert_allclose(lp.beta[v0], 4 * math.pi * 3.0, rtol=1e-12)
    d = lp.d_in[v0]
    # isotropic: the fraction going down (z < 0) is 1/2 within 4 standard errors
    frac = (d[:, 2] < 0).mean()
    assert abs(frac - 0.5) < 4 * 0.5 / math.sqrt(d.shape[0])


def test_open_scene_drops_escaped_paths_and_recycled_memory_changes_nothing():
    """In an open scene most light paths leave from their emitter: they are not recorded (no edge,
    no photon), every recorded path keeps >= 2 vertices. Records traced into memory handed back
    with ``recycle`` equal a fresh tracer's, and records not handed back are never overwritten."""
    sa = compile_scene(gdlearn.scene.load(str(ROOT / "scenes/caustic-closeup.xml"), res=8))
    n = 4000
    fresh = LightTracer(sa, PARAMS).trace(5, 1, 0, n)
    paths, counts = np.unique(fresh.path, return_counts=True)
    assert 0 < paths.size < n and (counts >= 2).all()
    assert (fresh.kind[fresh.depth == 0] == K_EMITTER).sum() == paths.size
    lt = LightTracer(sa, PARAMS)
    kept = lt.trace(5, 0, 0, n)
    snapshot = [f.copy() for f in kept]
    other = lt.trace(5, 3, 0, n)                 # not recycled: `kept` must stay as it was
    assert all(np.array_equal(a, b) for a, b in zip(snapshot, kept))
    lt.recycle(other)
    again = lt.trace(5, 1, 0, n)                 # written into other's memory
    assert again.pos.base is other.pos.base
    for name, x, y in zip(fresh._fields, fresh, again):
        assert np.array_equal(x, y), name
