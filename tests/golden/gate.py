"""The gate every recording in tests/golden/ is checked with: counters and integer buffers
identical, floating-point buffers equal to 1e-12 of the buffer's largest value.

Not bit for bit: numba compiles for the host CPU, and a machine with AVX-512 and FMA vectorises and
contracts a few sums differently from one with AVX2 (the recording machine and the CI machine differ
by one ulp, 5.6e-17, on Cornell-box pixels of order 1e-2). A refactoring that changes one random
number, one sample's weight or one bounce moves pixels by 1e-4 or more of the scale, eight orders of
magnitude above the gate (tests/test_golden_outputs.py::test_the_gate_sees_one_changed_sample).
"""
from __future__ import annotations

import numpy as np

#: relative to the buffer's largest |value|
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
