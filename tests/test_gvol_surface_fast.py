"""The surface pass of the volumetric full images (gvol_surface, G-VPM's and G-BRE's) on GPM's fast
photon loop (photon_shift_loop: the photon's parent found and re-evaluated towards the base direction
once, its recorded edge walked once, for the four neighbours; the pixel's buffers summed in a row
scratch in photon order and written once) computes exactly what the straightforward kernel it
replaced computed (tests/_gvol_surface_reference.py: one photon at a time, four calls of the shift,
a buffer write per term): the same random numbers, photons and sums in the same order, so every
buffer -- phi, le, M, the footprints, the shift counts and the dropped terms -- is equal bit for bit,
on the fog box (surfaces seen and lit through a homogeneous medium filling the scene), the spot
medium (photon edges through the null faces of a smoke block, medium parents) and the volume
caustic (glass above the medium). None of these has a photon whose specular chain and edge lie in
vacuum, so the manifold branch is not compared here (tests/test_gpm_fast.py covers GPM's).

The test does catch a wrong kernel: with the MIS weight in photon_shift_loop._add_shift perturbed by
one part in 1e12 (``wgt * (1 + 1e-12)``) all three cases fail on ``phi`` (max difference 3e-11 to
1e-10; checked by hand when the test was written)."""
from __future__ import annotations

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.photon import gpm_gather as gg
from gdlearn.integrators.photon import gvol_surface as gs
from gdlearn.scene.load import load
import _gvol_surface_reference as ref

SCENES = ["scenes/fog-box.xml", "scenes/spot-medium.xml", "scenes/volume-caustic.xml"]


@pytest.mark.parametrize("path", SCENES)
def test_shared_loop_equals_the_reference_bit_for_bit(path):
    g = make("gvpm", load(path, res=14), seed=5, photons_per_pass=6000, transport="all")
    g.render_pass(0)                            # the progressive radii of pass 0, reduced
    lp = g.trace_photons(1)
    _, sgrids, _, _ = g.build(lp)
    radius = np.sqrt(g.r2)
    outs = []
    for rows in (gs.surface_rows, ref.reference_rows):
        out = gg.allocate(g.height, g.width)
        with g.setup.parallel(g.height):
            rows(g.setup.sa, lp, sgrids, g.mtab, g.gather_params, g.seed, 2, radius, out)
        outs.append(out)
    fast, slow = outs
    for name, a, b in zip(gg.GpmOut._fields, fast, slow):
        assert np.array_equal(a, b), f"{name}: max |fast - reference| {np.abs(a - b).max():.3e}"
    # the comparison must see reconnected and failed shifts, emission (the fog box's and the volume
    # caustic's emitters are in view), and D_k / S_k buffers that are not all zero
    c = slow.count.sum(axis=(0, 2, 3))
    assert c[gg.RECONNECTED] > 1000 and c[gg.FAILED] > 100
    assert np.abs(slow.phi[:, 1:]).sum() > 0 and slow.m.sum() > 1000
