"""Every integrator's buffers on every shipped scene are bit-identical to the arrays recorded in
``tests/golden/`` (see ``tests/golden/record.py`` for the configurations and when to re-record).

Exact equality, not a tolerance: a refactoring that moves code must not change one random number
or one summation order. A change meant to alter results re-records the arrays in the same commit
and says why.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import record  # noqa: E402

CONFIGS = list(record.configurations())


@pytest.mark.parametrize("stem,scene,integrator,options", CONFIGS, ids=[c[0] for c in CONFIGS])
def test_buffers_are_bit_identical_to_the_recording(stem, scene, integrator, options):
    want = np.load(record.HERE / f"{stem}.npz")
    got = record.run(scene, integrator, options)
    assert sorted(got) == sorted(want.files), "a buffer or counter appeared or disappeared"
    for name in want.files:
        a, b = want[name], got[name]
        assert a.shape == b.shape and np.array_equal(a, b), f"{stem}: {name} differs " \
            f"(max |diff| {np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))):.3g})"
