"""The surface pass of the volumetric full images (gvol_surface, G-VPM's and G-BRE's) on GPM's fast
photon loop (photon_shift_loop: the photon's parent found and re-evaluated towards the base direction
once, its recorded edge walked once, for the four neighbours; the pixel's buffers summed in a row
scratch in photon order and written once) computes what the straightforward kernel it replaced
computed (tests/_gvol_surface_reference.py: one photon at a time, four calls of the shift, a buffer
write per term): the same random numbers, photons and sums in the same order. Every buffer -- phi,
le, M, the footprints, the shift counts and the dropped terms -- reproduces the reference kernel's
recording (tests/golden/passes.py; counts exactly, the rest to rounding, tests/golden/gate.py) on
the fog box (surfaces seen and lit through a homogeneous medium filling the scene), the spot medium
(photon edges through the null faces of a smoke block, medium parents) and the volume caustic (glass
above the medium). None of these has a photon whose specular chain and edge lie in vacuum, so the
manifold branch is not compared here (tests/test_gpm_fast.py covers GPM's).

The test does catch a wrong kernel: with the MIS weight in photon_shift_loop._add_shift perturbed by
one part in 1e9 (``wgt * (1 + 1e-9)``) all three cases fail on ``phi`` (checked by hand, 2026-12-07)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import passes  # noqa: E402
from gdlearn.integrators.photon import gpm_gather as gg  # noqa: E402

CASES = passes.cases("gvol_surface")


@pytest.mark.parametrize("stem,family,scene,options", CASES, ids=[c[2] for c in CASES])
def test_shared_loop_reproduces_the_reference_kernel(stem, family, scene, options):
    ref = passes.check(stem, family, scene, options)
    # the recording must hold reconnected and failed shifts, emission (the fog box's and the volume
    # caustic's emitters are in view), and D_k / S_k buffers that are not all zero
    c = ref["count"].sum(axis=(0, 2, 3))
    assert c[gg.RECONNECTED] > 1000 and c[gg.FAILED] > 100
    assert np.abs(ref["phi"][:, 1:]).sum() > 0 and ref["m"].sum() > 1000
