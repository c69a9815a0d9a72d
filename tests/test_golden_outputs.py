"""Every integrator's buffers on every shipped scene match the arrays recorded in ``tests/golden/``
(see ``tests/golden/record.py`` for the configurations and when to re-record).

Counters and integer buffers must be identical. Floating-point buffers must agree to 1e-12 of the
buffer's largest value. That is a rounding-level gate: numba compiles for the host CPU, and a
machine with AVX-512 and FMA vectorises and contracts a few sums differently from one with AVX2
(the recording machine and the CI machine differ by one ulp, 5.6e-17, on Cornell-box pixels of
order 1e-2). A refactoring that changes one random number, one sample's weight or one bounce
moves pixels by 1e-4 or more of the scale, eight orders of magnitude above the gate. A change
meant to alter results re-records the arrays in the same commit and says why.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import record  # noqa: E402

CONFIGS = list(record.configurations())
#: relative to the buffer's largest |value|; see the module docstring for why not exact
ROUNDING = 1e-12


def mismatch(want: np.ndarray, got: np.ndarray) -> str | None:
    """Why ``got`` does not reproduce ``want`` (None when it does)."""
    if want.shape != got.shape or want.dtype.kind != got.dtype.kind:
        return f"shape/dtype {want.shape} {want.dtype} vs {got.shape} {got.dtype}"
    if want.dtype.kind != "f":
        return None if np.array_equal(want, got) else "integer values differ"
    if not np.array_equal(np.isfinite(want), np.isfinite(got)):
        return "non-finite entries differ"
    fin = np.isfinite(want)
    diff = np.max(np.abs(want[fin] - got[fin]), initial=0.0)
    scale = np.max(np.abs(want[fin]), initial=0.0)
    return None if diff <= ROUNDING * scale else f"max |diff| {diff:.3g} at scale {scale:.3g}"


def test_the_gate_sees_one_changed_sample():
    """A buffer with one pixel moved by a plausible one-sample change fails; one ulp passes."""
    rng = np.random.default_rng(0)
    a = rng.random((12, 12, 3)) * 1e-2
    assert mismatch(a, np.nextafter(a, 1.0)) is None
    b = a.copy()
    b[3, 4, 1] += 1e-2 / 8 * 1e-3          # one of 8 samples of one pixel off by 0.1 %
    assert mismatch(a, b) is not None
    assert mismatch(np.arange(4), np.arange(4) + (np.arange(4) == 2)) is not None


@pytest.mark.parametrize("stem,scene,integrator,options", CONFIGS, ids=[c[0] for c in CONFIGS])
def test_buffers_match_the_recording(stem, scene, integrator, options):
    want = np.load(record.HERE / f"{stem}.npz")
    got = record.run(scene, integrator, options)
    assert sorted(got) == sorted(want.files), "a buffer or counter appeared or disappeared"
    for name in want.files:
        why = mismatch(want[name], np.asarray(got[name]))
        assert why is None, f"{stem}: {name} differs ({why})"
