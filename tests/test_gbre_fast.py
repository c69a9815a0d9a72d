"""The fast G-BRE camera pass (gbre_gather: a photon's recorded edge walked once for its four
neighbours, the pixel's sums in registers written once, the per-photon helpers inlined) computes
what the kernel it replaced computed (tests/_gbre_reference.py: one photon at a time, four shifts
through non-inlined calls, a buffer write per term, the recorded edge walked again per neighbour):
the same beams, photons, chord points and sums in the same order. Every buffer -- L, D_k, S_k, the
photon counts M, the shift counts and the dropped terms -- reproduces the reference kernel's
recording (tests/golden/passes.py; counts exactly, the rest to rounding, tests/golden/gate.py). On
the fog box (no null interfaces: analytic recorded edges) and the spot medium (every reconnection
walks through the block's null top), the 3D kernel with the mixed and the simple shift and the 2D
kernel (the ray-frame copy), with photon subsets on and off."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import passes  # noqa: E402
from gdlearn.integrators.photon import gvpm_gather as gg  # noqa: E402

CASES = passes.cases("gbre")


@pytest.mark.parametrize("stem,family,scene,options", CASES, ids=[c[0].split("__", 1)[1] for c in CASES])
def test_fast_pass_reproduces_the_reference_kernel(stem, family, scene, options):
    ref = passes.check(stem, family, scene, options)
    # the recording must hold every kind of term: reconnected and failed shifts (and, for the mixed
    # shift, null and reflected ones), and D_k / S_k buffers that are not all zero
    c = ref["count"].sum(axis=(0, 2, 3))
    assert c[gg.C_RECONNECTED] > 1000 and c[gg.C_FAILED] > 100, c
    assert options.get("shift") != "mixed" or (c[gg.C_NULL] > 1000 and c[gg.C_MIXED] > 100), c
    assert np.abs(ref["phi"][:, 1:]).sum() > 0 and ref["m"].sum() > 1000
