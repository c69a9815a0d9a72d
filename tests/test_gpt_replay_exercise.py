"""The "replay" exercise catches the plausible wrong answers: Algorithm 1 typed literally into numpy
(backward shifts at x = 0 / y = 0 wrap to the last column / row), the forward shift alone with
weight 1 (unbiased, but not Algorithm 1), offsets with fresh random numbers (no replay), and a
reconstruction that divides by 5 at the border. Each wrong stub must fail `gdlearn check replay`
(run in a child process on a copy of the exercise), while the reference solution passes."""
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EX = ROOT / "exercises"

#: Bound on one child process (it may JIT-compile numba kernels cold, which took > 120 s on a busy
#: 2-core machine). It only bounds a hang: subprocess.run kills the child when it expires, and no
#: assertion depends on how long the child took.
SUBPROCESS_TIMEOUT = 1800

SOLUTION = (EX / "_solutions" / "replay.py").read_text()

LITERAL_ALGORITHM_1 = '''
import numpy as np
from gdlearn.reconstruct import control_variates


def accumulate(radiance, width, height, spp, seed, dims=4):
    rng = np.random.default_rng(seed)
    P, Gx, Gy = np.zeros((height, width)), np.zeros((height, width)), np.zeros((height, width))
    for y in range(height):
        for x in range(width):
            for _ in range(spp):
                u = rng.random(dims)
                fx, fy = x + u[0], y + u[1]
                base = radiance(u, fx, fy)
                P[y, x] += base
                if x > 0 or True:
                    Gx[y, x - 1] += 0.5 * (base - radiance(u, fx - 1, fy))
                    Gy[y - 1, x] += 0.5 * (base - radiance(u, fx, fy - 1))
                if x + 1 < width:
                    Gx[y, x] += 0.5 * (radiance(u, fx + 1, fy) - base)
                if y + 1 < height:
                    Gy[y, x] += 0.5 * (radiance(u, fx, fy + 1) - base)
    return P / spp, Gx / spp, Gy / spp

def reconstruct(P, Gx, Gy, iterations=50):
    return control_variates(P, Gx, Gy, iterations=iterations).image
'''

WRONG = {
    "literal Algorithm 1 (index -1 wraps)": LITERAL_ALGORITHM_1,
    "forward shift only, weight 1": SOLUTION.replace(
        "if 0 <= nx < width and 0 <= ny < height:", "if 0 <= nx < width and 0 <= ny < height and k in (0, 2):"
    ).replace("gx, gy = combine_gradients(diffs / spp)", "gx, gy = combine_gradients(diffs / spp, (1.0, 0.0))"),
    "fresh random numbers for offsets": SOLUTION.replace(
        "diffs[k, y, x] += radiance(u, nx + u[0], ny + u[1]) - base",
        "v = rng.random(dims); diffs[k, y, x] += radiance(v, nx + v[0], ny + v[1]) - base"),
    "reconstruct divides by 5 everywhere": SOLUTION.replace(
        "return control_variates(P, Gx, Gy, iterations=iterations).image", textwrap.dedent('''\
    I = np.array(P, dtype=float)
        for _ in range(iterations):
            J = I.copy() * 1.0
            J[:, 1:] += I[:, :-1] + Gx[:, :-1]
            J[:, :-1] += I[:, 1:] - Gx[:, :-1]
            J[1:, :] += I[:-1, :] + Gy[:-1, :]
            J[:-1, :] += I[1:, :] - Gy[:-1, :]
            I = J / 5.0
        return I''')),
}


def _check(folder: Path) -> tuple[int, str]:
    code = (f"import pathlib, sys; import gdlearn.teaching.exercises as e; e.EXERCISES_DIR = pathlib.Path({str(folder)!r}); "
            "e.SOLUTIONS_DIR = e.EXERCISES_DIR / '_solutions'; r = e.check('replay'); print(r.text()); "
            "sys.exit(0 if r.ok else 1)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=SUBPROCESS_TIMEOUT)
    return res.returncode, res.stdout + res.stderr


@pytest.mark.parametrize("source", [SOLUTION] + list(WRONG.values()), ids=["solution"] + list(WRONG))
def test_the_checks_separate_right_from_wrong(tmp_path, source):
    work = tmp_path / "exercises"
    shutil.copytree(EX / "replay", work / "replay")
    (work / "_solutions").mkdir()
    (work / "replay" / "replay.py").write_text(source)
    rc, out = _check(work)
    if source is SOLUTION:
        assert rc == 0, out
    else:
        assert rc == 1 and "FAIL" in out, out
        assert "Traceback" not in out, out
