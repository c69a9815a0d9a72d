"""The fast GPM camera pass (gpm_gather: a gather point's photons collected once, the base parent
re-evaluated once per photon for the four neighbours, each neighbour's D_k, S_k and shift counts
summed in registers in photon order and written once) computes exactly what the straightforward
kernel it replaced computed (tests/_gpm_reference.py: one photon at a time, four calls of the
shift, a buffer write per term): the same random numbers, the same photons, the same sums in the
same order, so every buffer -- phi, le, M, the footprints, the shift counts and the dropped terms --
is equal bit for bit, on the Cornell box (reconnections only), the caustics box and the mirror
caustic (the manifold walk's branch).

The test does catch a wrong kernel: with the MIS weight of a reconnected shift perturbed by one
part in 1e12 in gpm_gather (``wgt * (1 + 1e-12)``) all three cases fail on ``phi`` (checked by
hand when the test was written, 2026-12-04)."""
from __future__ import annotations

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.photon import gpm_gather as gg
from gdlearn.scene.load import load
import _gpm_reference as ref


@pytest.mark.parametrize("path,manifold", [("scenes/cornell-box.xml", False), ("scenes/caustics-box.xml", True),
                                           ("scenes/mirror-caustic.xml", True)])
def test_fast_pass_equals_the_reference_bit_for_bit(path, manifold):
    g = make("gpm", load(path, res=14), seed=7, photons_per_pass=4000)
    g.render_pass(0)                            # the progressive radii of pass 0, reduced
    lp, grids = g.build(g.trace_photons(1))
    radius = np.sqrt(g.r2)
    outs = []
    for rows in (gg.gpm_rows, ref.reference_rows):
        out = gg.allocate(g.height, g.width)
        with g.setup.parallel(g.height):
            rows(g.setup.sa, lp, grids, g.mtab, g.gather_params, g.seed, 2, radius, out)
        outs.append(out)
    fast, slow = outs
    for name, a, b in zip(gg.GpmOut._fields, fast, slow):
        assert np.array_equal(a, b), f"{name}: max |fast - reference| {np.abs(a - b).max():.3e}"
    # the comparison must see every kind of term: reconnected and failed shifts (and manifold ones
    # where the scene has a mirror), emission, and D_k / S_k buffers that are not all zero
    c = slow.count.sum(axis=(0, 2, 3))
    assert c[gg.RECONNECTED] > 1000 and c[gg.FAILED] > 100
    assert not manifold or c[gg.MANIFOLD] > 20
    assert np.abs(slow.phi[:, 1:]).sum() > 0 and np.abs(slow.le).sum() > 0 and slow.m.sum() > 1000
