"""Every integrator's buffers on every shipped scene match the arrays recorded in ``tests/golden/``
(see ``tests/golden/record.py`` for the configurations and when to re-record).

Counters and integer buffers must be identical, floating-point buffers equal to 1e-12 of the
buffer's largest value (``tests/golden/gate.py`` says why not bit for bit). A change meant to alter
results re-records the arrays in the same commit and says why.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import record  # noqa: E402
from gate import mismatch  # noqa: E402

CONFIGS = list(record.configurations())


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
