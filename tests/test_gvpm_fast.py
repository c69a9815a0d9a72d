"""The fast G-VPM camera pass (gvpm_gather: a distance sample's photons collected once, each
neighbour's shifts summed in registers, a photon's recorded edge walked once for all neighbours)
computes exactly what the straightforward kernel it replaced computed (tests/_gvpm_reference.py: one
photon at a time, four shifts, a buffer write per term): the same random numbers, the same photons,
the same sums in the same order, so every buffer -- L, D_k, S_k, the photon counts M and the shift
counts -- is equal bit for bit, on the fog box (no null interfaces: analytic recorded edges) and on
the spot medium (every reconnection walks through the block's null top), for both shifts."""
from __future__ import annotations

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.photon import gvpm_gather as gg
from gdlearn.scene.load import load
import _gvpm_reference as ref


@pytest.mark.parametrize("path", ["scenes/fog-box.xml", "scenes/spot-medium.xml"])
@pytest.mark.parametrize("shift", ["mixed", "simple"])
def test_fast_pass_equals_the_reference_bit_for_bit(path, shift):
    # VPM's default radius, not gvpm's smaller one: the comparison must see many shifts of every kind
    g = make("gvpm", load(path, res=12), seed=5, photons_per_pass=3000, transport="media", shift=shift,
             volume_radius_scale=1.0)
    g.render_pass(0)                            # the progressive radii of pass 0, reduced
    lp = g.trace_photons(1)
    _, _, vgrids, _ = g.build(lp)
    outs = []
    for fast in (True, False):
        out = gg.allocate(g.height, g.width)
        with g.setup.parallel(g.height):
            if fast:        # no specular parent in these scenes: the manifold branch is never taken
                gg.gvpm_rows(g.setup.sa, lp, vgrids, g.mtab, g.gather_params, g.gv, g.seed, 2, g.rv, out)
            else:
                ref.reference_rows(g.setup.sa, lp, vgrids, g.gather_params, g.gv, g.seed, 2, g.rv, out)
        outs.append(out)
    fast, slow = outs
    for name, a, b in zip(gg.GvpmOut._fields, fast, slow):
        assert np.array_equal(a, b), f"{name}: max |fast - reference| {np.abs(a - b).max():.3e}"
    # the comparison must see every kind of term: reconnected shifts (and, for mixed, null and
    # reflected ones), failures, and D_k / S_k buffers that are not all zero
    c = slow.count.sum(axis=(0, 2, 3))
    assert c[gg.C_RECONNECTED] > 1000 and c[gg.C_FAILED] > 100
    assert shift == "simple" or (c[gg.C_NULL] > 1000 and c[gg.C_MIXED] > 100)
    assert np.abs(slow.phi[:, 1:]).sum() > 0 and slow.m.sum() > 1000
