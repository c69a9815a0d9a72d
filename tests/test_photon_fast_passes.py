"""The photon estimators' fast camera passes compute what the straightforward kernels they replaced
computed -- the same random numbers, the same photons, the same sums in the same order -- so every
buffer reproduces the reference kernel's recording (tests/golden/passes.py records them with the
kernels kept in tests/_*_reference.py): counts exactly, the rest to rounding (tests/golden/gate.py).

* **GPM** (gpm_gather: a gather point's photons collected once, the base parent re-evaluated once
  per photon for the four neighbours, each neighbour's D_k, S_k and shift counts summed in registers
  in photon order and written once; the reference: one photon at a time, four calls of the shift,
  a buffer write per term) on the Cornell box (reconnections only), the caustics box and the mirror
  caustic (the manifold walk's branch). Buffers phi, le, M, the footprints, the shift counts and
  the dropped terms.
* **The surface pass of the volumetric full images** (gvol_surface, G-VPM's and G-BRE's, on GPM's
  photon loop: the photon's parent found and re-evaluated once, its recorded edge walked once, for
  the four neighbours) on the fog box (surfaces seen and lit through a medium filling the scene),
  the spot medium (photon edges through the null faces of a smoke block, medium parents) and the
  volume caustic (glass above the medium). None of these has a photon whose specular chain and edge
  lie in vacuum, so its manifold branch is GPM's, compared above.
* **G-VPM** (gvpm_gather: a distance sample's photons collected once, each neighbour's shifts summed
  in registers, a photon's recorded edge walked once for all neighbours) and **G-BRE** (gbre_gather:
  the same for beams, the per-photon helpers inlined; its reference calls them and walks the edge
  again per neighbour) on the fog box (no null interfaces: analytic recorded edges) and the spot
  medium (every reconnection walks through the block's null top): both shifts, G-BRE's 2D kernel
  (the ray-frame copy), photon subsets on and off.

The test catches a wrong kernel: with the MIS weight perturbed by one part in 1e9
(``wgt * (1 + 1e-9)`` in photon_shift_loop._add_shift, gvpm_gather and gbre_gather) all 20 cases
fail on ``phi``, at about 5e-10 of its scale (checked by hand, 2026-12-07; when the references ran
beside the fast kernels, the same check caught 1e-12)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import passes  # noqa: E402
from gdlearn.integrators.photon import gpm_gather as gpm  # noqa: E402
from gdlearn.integrators.photon import gvpm_gather as gvpm  # noqa: E402

CASES = passes.cases()


def _surface_terms(ref, scene, options):
    """Reconnected and failed shifts (and manifold ones where the scene has a mirror), emission where
    an emitter is in view, and D_k / S_k buffers that are not all zero."""
    c = ref["count"].sum(axis=(0, 2, 3))
    assert c[gpm.RECONNECTED] > 1000 and c[gpm.FAILED] > 100, c
    assert scene not in ("caustics-box", "mirror-caustic") or c[gpm.MANIFOLD] > 20, c
    assert np.abs(ref["phi"][:, 1:]).sum() > 0 and ref["m"].sum() > 1000
    assert scene == "spot-medium" or np.abs(ref["le"]).sum() > 0


def _medium_terms(ref, scene, options):
    """Reconnected and failed shifts (and, for the mixed shift, null and reflected ones), and D_k /
    S_k buffers that are not all zero."""
    c = ref["count"].sum(axis=(0, 2, 3))
    assert c[gvpm.C_RECONNECTED] > 1000 and c[gvpm.C_FAILED] > 100, c
    assert options.get("shift") != "mixed" or (c[gvpm.C_NULL] > 1000 and c[gvpm.C_MIXED] > 100), c
    assert np.abs(ref["phi"][:, 1:]).sum() > 0 and ref["m"].sum() > 1000


#: what a family's recording must hold for the comparison to mean something
TERMS = {"gpm": _surface_terms, "gvol_surface": _surface_terms, "gvpm": _medium_terms, "gbre": _medium_terms}


@pytest.mark.parametrize("stem,family,scene,options", CASES, ids=[c[0] for c in CASES])
def test_fast_pass_reproduces_the_reference_kernel(stem, family, scene, options):
    TERMS[family](passes.check(stem, family, scene, options), scene, options)
