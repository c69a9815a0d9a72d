"""The fast GPM camera pass (gpm_gather: a gather point's photons collected once, the base parent
re-evaluated once per photon for the four neighbours, each neighbour's D_k, S_k and shift counts
summed in registers in photon order and written once) computes what the straightforward kernel it
replaced computed (tests/_gpm_reference.py: one photon at a time, four calls of the shift, a
buffer write per term): the same random numbers, the same photons, the same sums in the same order.
Every buffer -- phi, le, M, the footprints, the shift counts and the dropped terms -- reproduces
the reference kernel's recording (tests/golden/passes.py) on the Cornell box (reconnections only),
the caustics box and the mirror caustic (the manifold walk's branch): counts exactly, the rest to
rounding (tests/golden/gate.py).

The test does catch a wrong kernel: with the MIS weight of a reconnected shift perturbed by one
part in 1e9 in gpm_gather (``wgt * (1 + 1e-9)``) all three cases fail on ``phi`` (checked by hand,
2026-12-07; when the reference ran beside the fast kernel, the same check caught 1e-12)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import passes  # noqa: E402
from gdlearn.integrators.photon import gpm_gather as gg  # noqa: E402

CASES = passes.cases("gpm")


@pytest.mark.parametrize("stem,family,scene,options", CASES, ids=[c[2] for c in CASES])
def test_fast_pass_reproduces_the_reference_kernel(stem, family, scene, options):
    ref = passes.check(stem, family, scene, options)
    # the recording must hold every kind of term: reconnected and failed shifts (and manifold ones
    # where the scene has a mirror), emission, and D_k / S_k buffers that are not all zero
    c = ref["count"].sum(axis=(0, 2, 3))
    assert c[gg.RECONNECTED] > 1000 and c[gg.FAILED] > 100
    assert scene == "cornell-box" or c[gg.MANIFOLD] > 20
    assert np.abs(ref["phi"][:, 1:]).sum() > 0 and np.abs(ref["le"]).sum() > 0 and ref["m"].sum() > 1000
