"""The fast G-BRE camera pass (gbre_gather: a photon's recorded edge walked once for its four
neighbours, the pixel's sums in registers written once, the per-photon helpers inlined) computes
exactly what the kernel it replaced computed (tests/_gbre_reference.py: one photon at a time, four
shifts through non-inlined calls, a buffer write per term, the recorded edge walked again per
neighbour): the same beams, photons, chord points and sums in the same order, so every buffer -- L,
D_k, S_k, the photon counts M, the shift counts and the dropped terms -- is equal bit for bit. On the
fog box (no null interfaces: analytic recorded edges) and the spot medium (every reconnection walks
through the block's null top), the 3D kernel with the mixed and the simple shift and the 2D kernel
(the ray-frame copy), with photon subsets on and off."""
from __future__ import annotations

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.photon import gbre_gather as gb
from gdlearn.integrators.photon import gvpm_gather as gg
from gdlearn.scene.load import load
import _gbre_reference as ref

VARIANTS = [dict(kernel="3d", shift="mixed"), dict(kernel="3d", shift="simple"), dict(kernel="2d"),
            dict(kernel="3d", shift="mixed", subsets=False), dict(kernel="2d", subsets=False)]


def _both(path, kw):
    """One pass's photons and radius (pass 1: the global schedule already reduced), gathered by the
    fast kernel and by the reference: (fast GvpmOut, reference GvpmOut)."""
    # the BRE's default radius, not gbre's smaller one: the comparison must see many shifts of every kind
    g = make("gbre", load(path, res=12), seed=5, photons_per_pass=3000, transport="media", volume_radius_scale=1.0,
             **kw)
    g.render_pass(0)
    lp = g.trace_photons(1)
    _, bbhs, r, _ = g.build(lp)
    outs = []
    for fast in (True, False):
        out = gg.allocate(g.height, g.width)
        with g.setup.parallel(g.height):
            if fast:        # no specular parent in these scenes: the manifold branch is never taken
                gb.gbre_rows(g.setup.sa, lp, bbhs, g.mtab, float(r), g.gather_params, g.gp, g.wsub, g.seed, 2, out)
            else:
                ref.reference_rows(g.setup.sa, lp, bbhs, float(r), g.gather_params, g.gp, g.wsub, g.seed, 2, out)
        outs.append(out)
    return outs


@pytest.mark.parametrize("path", ["scenes/fog-box.xml", "scenes/spot-medium.xml"])
@pytest.mark.parametrize("kw", VARIANTS, ids=lambda kw: "-".join(str(v) for v in kw.values()))
def test_fast_pass_equals_the_reference_bit_for_bit(path, kw):
    fast, slow = _both(path, kw)
    for name, a, b in zip(gg.GvpmOut._fields, fast, slow):
        assert np.array_equal(a, b), f"{name}: max |fast - reference| {np.abs(a - b).max():.3e}"
    # the comparison must see every kind of term: reconnected and failed shifts (and, for the mixed
    # shift, null and reflected ones), and D_k / S_k buffers that are not all zero
    c = slow.count.sum(axis=(0, 2, 3))
    assert c[gg.C_RECONNECTED] > 1000 and c[gg.C_FAILED] > 100, c
    assert kw.get("shift") != "mixed" or (c[gg.C_NULL] > 1000 and c[gg.C_MIXED] > 100), c
    assert np.abs(slow.phi[:, 1:]).sum() > 0 and slow.m.sum() > 1000
