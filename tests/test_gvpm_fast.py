"""The fast G-VPM camera pass (gvpm_gather: a distance sample's photons collected once, each
neighbour's shifts summed in registers, a photon's recorded edge walked once for all neighbours)
computes what the straightforward kernel it replaced computed (tests/_gvpm_reference.py: one photon
at a time, four shifts, a buffer write per term): the same random numbers, the same photons, the
same sums in the same order. Every buffer -- L, D_k, S_k, the photon counts M and the shift counts --
reproduces the reference kernel's recording (tests/golden/passes.py; counts exactly, the rest to
rounding, tests/golden/gate.py) on the fog box (no null interfaces: analytic recorded edges) and on
the spot medium (every reconnection walks through the block's null top), for both shifts."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import passes  # noqa: E402
from gdlearn.integrators.photon import gvpm_gather as gg  # noqa: E402

CASES = passes.cases("gvpm")


@pytest.mark.parametrize("stem,family,scene,options", CASES, ids=[c[0].split("__", 1)[1] for c in CASES])
def test_fast_pass_reproduces_the_reference_kernel(stem, family, scene, options):
    ref = passes.check(stem, family, scene, options)
    # the recording must hold every kind of term: reconnected shifts (and, for mixed, null and
    # reflected ones), failures, and D_k / S_k buffers that are not all zero
    c = ref["count"].sum(axis=(0, 2, 3))
    assert c[gg.C_RECONNECTED] > 1000 and c[gg.C_FAILED] > 100
    assert options["shift"] == "simple" or (c[gg.C_NULL] > 1000 and c[gg.C_MIXED] > 100)
    assert np.abs(ref["phi"][:, 1:]).sum() > 0 and ref["m"].sum() > 1000
