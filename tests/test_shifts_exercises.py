"""The exercises of the chapter "Shift mappings" catch the plausible wrong answers.

reconnection-jacobian: the distance ratio alone (no cosines), the ratio upside down, the cosines
upside down, and the area-measure answer 1. halfvector-mirror: no Jacobian (1), the Jacobian upside
down, reflecting wi_o about the normal instead of the half vector, copying the base's outgoing
direction (a local-frame replay), and a copy that never fails. Each wrong stub must fail its
`gdlearn check` (run in a child process on a copy of the exercise, with readable feedback), while
the reference solution passes.
"""
from pathlib import Path

import pytest

from conftest import check_exercise_source

ROOT = Path(__file__).resolve().parent.parent
EX = ROOT / "exercises"


RECONNECTION = '''
import math
import numpy as np


def reconnection_jacobian(x_b, x_b_offset, y, n_y):
    d, do = np.subtract(y, x_b), np.subtract(y, x_b_offset)
    d2, do2 = float(d @ d), float(do @ do)
    if not (d2 > 0 and do2 > 0):
        return 0.0
    n = np.asarray(n_y, float)
    c = abs(n @ d) / math.sqrt(d2) if n.any() else 1.0
    co = abs(n @ do) / math.sqrt(do2) if n.any() else 1.0
    if not c > 0:
        return 0.0
    return float(FORMULA)
'''
RECONNECTION_WRONG = {
    "distances only": "d2 / do2",
    "upside down": "(c / co) * (do2 / d2) if co > 0 else 0.0",
    "cosines upside down": "(c / co) * (d2 / do2) if co > 0 else 0.0",
    "area-measure answer 1": "1.0",
}

MIRROR = '''
import numpy as np

def halfvector_copy_mirror(wi_b, wo_b, wi_o):
    wi_b, wo_b, wi_o = (np.asarray(v, float) for v in (wi_b, wo_b, wi_o))
    h = wi_b + wo_b
    h = h / np.linalg.norm(h)
    wo = DIRECTION
    if CHECK and (wi_o @ h <= 0 or wo[2] <= 0):
        return (0.0, 0.0, 0.0), 0.0, False
    return tuple(wo), float(JACOBIAN), True
'''
MIRROR_RIGHT = {"DIRECTION": "2 * (wi_o @ h) * h - wi_o", "CHECK": "True",
                "JACOBIAN": "abs(wo @ h) / abs(wo_b @ h)"}
MIRROR_WRONG = {
    "no Jacobian": {"JACOBIAN": "1.0"},
    "Jacobian upside down": {"JACOBIAN": "abs(wo_b @ h) / abs(wo @ h)"},
    "reflect about the normal": {"DIRECTION": "np.array([-wi_o[0], -wi_o[1], wi_o[2]])",
                                 "JACOBIAN": "1.0"},
    "copy the outgoing direction": {"DIRECTION": "wo_b.copy()", "JACOBIAN": "1.0"},
    "never fails": {"CHECK": "False"},
}


def _mirror(**parts):
    src = MIRROR
    for key, value in {**MIRROR_RIGHT, **parts}.items():
        src = src.replace(key, value)
    return src


CASES = ([("reconnection-jacobian", "solution", (EX / "_solutions" / "reconnection_jacobian.py").read_text(), True),
          ("reconnection-jacobian", "correct by hand", RECONNECTION.replace("FORMULA", "(co / c) * (d2 / do2)"), True)]
         + [("reconnection-jacobian", k, RECONNECTION.replace("FORMULA", v), False) for k, v in RECONNECTION_WRONG.items()]
         + [("halfvector-mirror", "solution", (EX / "_solutions" / "halfvector_mirror.py").read_text(), True),
            ("halfvector-mirror", "correct by hand", _mirror(), True)]
         + [("halfvector-mirror", k, _mirror(**v), False) for k, v in MIRROR_WRONG.items()])


@pytest.mark.parametrize("name, label, source, right", CASES, ids=[f"{c[0]}: {c[1]}" for c in CASES])
def test_the_checks_separate_right_from_wrong(tmp_path, name, label, source, right):
    rc, out = check_exercise_source(tmp_path, name, source)
    if right:
        assert rc == 0, out
    else:
        assert rc == 1 and "FAIL" in out, f"the wrong answer {label!r} passes every check:\n{out}"
        assert "Traceback" not in out, out
