"""Exercises never rot: every exercise's tests pass on its reference solution, fail on the untouched
stub with readable feedback, and catch a plausible wrong answer.

The exercise tests run in a child process (as `gdlearn check` would), so their imports and pytest's
state stay apart from this test session: conftest's ``check_exercise_source`` runs the checks on a
copy of the exercise with the stub replaced by a given source (the same helper as the media,
effects and shifts exercise tests).
"""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import check_exercise_source
from gdlearn.teaching.exercises import EXERCISES_DIR, SOLUTIONS_DIR, TARGET_ENV, list_exercises, module_name

#: Bound on one child process (it may JIT-compile numba kernels cold, which took > 120 s on a busy
#: 2-core machine). It only bounds a hang: subprocess.run kills the child when it expires, and no
#: assertion depends on how long the child took.
SUBPROCESS_TIMEOUT = 1800


ROOT = Path(__file__).resolve().parent.parent
EXERCISES = list_exercises()


def _env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    env.update(extra)
    return env


def test_there_is_an_exercise():
    assert "cosine-hemisphere" in EXERCISES


@pytest.mark.parametrize("name", EXERCISES)
def test_exercise_has_stub_readme_tests_and_solution(name):
    folder, mod = EXERCISES_DIR / name, module_name(name)
    for path in (folder / "README.md", folder / f"{mod}.py", folder / f"test_{mod}.py", SOLUTIONS_DIR / f"{mod}.py"):
        assert path.is_file(), f"exercise {name}: {path} is missing"


@pytest.mark.parametrize("name", EXERCISES)
def test_solution_passes_its_exercise_tests(name):
    # Plain pytest on the exercise folder, pointed at the solution: exactly what a maintainer runs.
    res = subprocess.run([sys.executable, "-m", "pytest", str(EXERCISES_DIR / name), "-q", "-p",
                          "no:cacheprovider", "-o", "addopts=", "--rootdir", str(EXERCISES_DIR)],
                         cwd=ROOT, env=_env(**{TARGET_ENV: "solution"}), capture_output=True, text=True,
                         timeout=SUBPROCESS_TIMEOUT)
    assert res.returncode == 0, f"the solution of {name} fails its tests:\n{res.stdout[-3000:]}"


def _pristine_stub(name: str) -> str:
    """The stub as the repository ships it: from git's HEAD, so that a student who solves an
    exercise in place (as its README says) does not turn this test red; the working copy only when
    git cannot tell (no repository, or a stub not committed yet)."""
    rel = f"exercises/{name}/{module_name(name)}.py"
    res = subprocess.run(["git", "show", f"HEAD:{rel}"], cwd=ROOT, capture_output=True, text=True)
    return res.stdout if res.returncode == 0 else (ROOT / rel).read_text()


@pytest.mark.parametrize("name", EXERCISES)
def test_stub_fails_with_readable_feedback(name, tmp_path):
    rc, out = check_exercise_source(tmp_path, name, _pristine_stub(name))
    assert rc == 1, f"the untouched stub of {name} should fail its checks:\n{out}"
    assert "FAIL" in out and "checks passed" in out, out
    assert "Traceback" not in out, f"feedback must not be a traceback wall:\n{out}"


def test_a_solved_stub_passes_in_place(tmp_path):
    """A student solves the exercise in its own folder: `gdlearn check` then passes, and the stub
    test above (which reads the pristine stub) is unaffected."""
    name = "mis-weights"
    rc, out = check_exercise_source(tmp_path, name, (SOLUTIONS_DIR / f"{module_name(name)}.py").read_text())
    assert rc == 0 and "Well done" in out, out


def test_wrong_distribution_is_caught(tmp_path):
    """A uniform-hemisphere warp with a self-consistent pdf: unit vectors, pdf integrates to 1, the
    estimator is even unbiased -- but it is not cosine-weighted, and the checks must say so."""
    rc, out = check_exercise_source(tmp_path, "cosine-hemisphere", textwrap.dedent("""
        import math
        import numpy as np

        def square_to_cosine_hemisphere(u1, u2):
            z = u1; r = math.sqrt(max(0.0, 1 - z * z)); phi = 2 * math.pi * u2
            return (r * math.cos(phi), r * math.sin(phi), z)

        def cosine_hemisphere_pdf(w):
            return 1 / (2 * math.pi) if w[2] >= 0 else 0.0

        def irradiance_estimate(sky, n, seed):
            u = np.random.default_rng(seed).random((n, 2))
            ws = [square_to_cosine_hemisphere(a, b) for a, b in u]
            return sum(sky(w) * w[2] / cosine_hemisphere_pdf(w) for w in ws) / n
        """))
    assert rc == 1, out
    failed = [line for line in out.splitlines() if line.strip().startswith("FAIL")]
    assert any("cosine law" in line for line in failed), out
    assert any("pdf(w) = cos(theta) / pi" in line for line in failed), out
    assert any("exactly, for every seed" in line for line in failed), out
    assert not any("unit vectors" in line for line in failed), out        # those parts are right


def test_sppm_update_without_the_flux_rescale_is_caught(tmp_path):
    """The classic slip of the SPPM exercise: the radius shrinks but tau is kept (tau' = tau + Phi),
    so old photons are counted as if they had fallen into the smaller disc. The checks must say so,
    and must still accept its N and R updates."""
    rc, out = check_exercise_source(tmp_path, "sppm-update", textwrap.dedent("""
        import math

        def progressive_update(N, r2, tau, M, phi, alpha):
            if N + M == 0:
                return N, r2, tau
            ratio = (N + alpha * M) / (N + M)
            return N + alpha * M, r2 * ratio, tau + phi

        def radiance(tau, r2, n_emitted):
            return tau / (math.pi * r2 * n_emitted)
        """))
    assert rc == 1, out
    failed = [line for line in out.splitlines() if line.strip().startswith("FAIL")]
    assert any("density form" in line for line in failed), out
    assert any("known density" in line for line in failed), out
    assert not any("radius never shrinks" in line for line in failed), out


#: the two classic slips of the BRE exercise: the kernel without its 1 / r^2 (K2 evaluated at d / r
#: but never divided by the disc's scale), and Silverman's biweight with the 2D Epanechnikov's 2/pi
_BRE_SOLUTION = (SOLUTIONS_DIR / "bre_kernel.py").read_text()
BRE_BUGS = {
    "without the 1/r^2": (_BRE_SOLUTION.replace("/ (r * r) * math.exp", "* math.exp"),
                          ["one photon by hand", "brute force"], "misses its 1 / r^2"),
    "with the wrong normalisation": (_BRE_SOLUTION.replace("return 3.0 / math.pi * a * a", "return 2.0 / math.pi * a * a"),
                                     ["K2(0) = 3/pi", "int_0^1 K2(x) 2 pi x dx = 1", "gdlearn's compiled kernel",
                                      "one photon by hand", "brute force"], "does not depend on r"),
}


@pytest.mark.parametrize("bug", sorted(BRE_BUGS))
def test_bre_kernel_with_a_planted_bug_is_caught(tmp_path, bug):
    """A BRE kernel without the 1/r^2, or with the biweight scaled by 2/pi instead of 3/pi: the checks
    must fail the tests that see it (the brute-force measurement saying which), and pass the others
    (the conditions 0 < t < s and d < r are still right)."""
    source, failing, hint = BRE_BUGS[bug]
    assert source != _BRE_SOLUTION, "the planted bug no longer matches the solution's text"
    rc, out = check_exercise_source(tmp_path, "bre-kernel", source)
    assert rc == 1, out
    failed = [line for line in out.splitlines() if line.strip().startswith("FAIL")]
    for label in failing:
        assert any(label in line for line in failed), (label, out)
    assert hint in out, out
    assert not any("0 unless 0 < t < s" in line for line in failed), out
    assert len(failed) == len(failing), out


#: the classic slips of the offset-photon exercise: Eq. 5 copied in world space (y* = z' + (y - z),
#: right on one flat surface, wrong wherever the frames turn), Eq. 6 upside down, and Eq. 6 with the
#: hit's normal at y* as well (cos' for cos*)
_OFFSET_SOLUTION = (SOLUTIONS_DIR / "offset_photon.py").read_text()
OFFSET_BUGS = {
    "copied in world space": (
        _OFFSET_SOLUTION.replace("return tuple(z_o[k] + a * s_o[k] + b * t_o[k] + c * n_o[k] for k in range(3))",
                                 "return tuple(z_o[k] + r[k] for k in range(3))"),
        ["the coordinates that y - z has in the base frame", "lands in the offset's tangent plane",
         "(gdlearn.shifts.photon.offset_target)"], "copied in world space"),
    "Eq. 6 upside down": (
        _OFFSET_SOLUTION.replace("return (cos_star / da) / (cos_hit / db)", "return (cos_hit / db) / (cos_star / da)"),
        ["by hand -- y' twice as far", "onto a sphere", "onto a tilted plane",
         "(gdlearn.shifts.photon.projection_jacobian)"], "upside down"),
    "cos' for cos*": (
        _OFFSET_SOLUTION.replace("cos_star = abs(_dot(n_star, a))", "cos_star = abs(_dot(n_hit, a))"),
        ["onto a sphere", "onto a tilted plane", "(gdlearn.shifts.photon.projection_jacobian)"],
        "cos* belongs to n*"),
}


@pytest.mark.parametrize("bug", sorted(OFFSET_BUGS))
def test_offset_photon_with_a_planted_bug_is_caught(tmp_path, bug):
    """An offset photon copied in world space instead of through the frames, or a projection
    Jacobian upside down or with the wrong normal at y*: the checks must fail the tests that see it
    (saying which slip it is), and pass the others (shifting back undoes a world-space copy too, and
    the degenerate cases are still right)."""
    source, failing, hint = OFFSET_BUGS[bug]
    assert source != _OFFSET_SOLUTION, "the planted bug no longer matches the solution's text"
    rc, out = check_exercise_source(tmp_path, "offset-photon", source)
    assert rc == 1, out
    failed = [line for line in out.splitlines() if line.strip().startswith("FAIL")]
    for label in failing:
        assert any(label in line for line in failed), (label, out)
    assert hint in out, out
    assert not any("shifted back from z' to z" in line or "never NaN" in line for line in failed), out
    assert len(failed) == len(failing), out


#: the classic slips of the mixed-shift exercise (Gruson et al. 2018, Eq. 16): the reflection across
#: the plane through d instead of d', the reflection forgotten (b' = b* for every photon outside K'),
#: and the reflection decided by "b* outside K'" instead of "b* in K" (b* is always in K', so it never
#: fires: the same map as the forgotten one, and the checks must name that reading too)
_MIXED_SOLUTION = (SOLUTIONS_DIR / "mixed_shift.py").read_text()
_MIXED_COMMON = ["across the plane through d'", "returns every photon", "uniform over K'", "compiled version"]
MIXED_BUGS = {
    "reflected through d": (
        _MIXED_SOLUTION.replace("k = 2.0 * sum(u[i] * (d_off[i] - bs[i])", "k = 2.0 * sum(u[i] * (d[i] - bs[i])"),
        _MIXED_COMMON + ["every image b'"], "reflected across the plane through d: the plane passes through d'"),
    "reflection forgotten": (
        _MIXED_SOLUTION.replace("    if not _dist2(bs, d) < r * r:                         # outside K: nothing else "
                                "maps there\n        return bs, \"translated\"", "    return bs, \"translated\""),
        _MIXED_COMMON, "the reflection is missing"),
    "reflected whenever b* is outside K'": (
        _MIXED_SOLUTION.replace("if not _dist2(bs, d) < r * r:", "if _dist2(bs, d_off) < r * r:"),
        _MIXED_COMMON, "a test 'b* outside K'' never fires"),
}


@pytest.mark.parametrize("bug", sorted(MIXED_BUGS))
def test_mixed_shift_with_a_planted_bug_is_caught(tmp_path, bug):
    """A mixed shift that reflects across the plane through d, forgets the reflection, or reflects when
    b* lies outside K' (never): the checks must fail the tests that see it (the hand value saying
    which slip it is), and pass the others (the null and the translated branch are still right, and
    without the reflection every image still lies in K')."""
    source, failing, hint = MIXED_BUGS[bug]
    assert source != _MIXED_SOLUTION, "the planted bug no longer matches the solution's text"
    rc, out = check_exercise_source(tmp_path, "mixed-shift", source)
    assert rc == 1, out
    failed = [line for line in out.splitlines() if line.strip().startswith("FAIL")]
    for label in failing:
        assert any(label in line for line in failed), (label, out)
    assert hint in out, out
    assert not any("is kept (the null branch)" in line or "is translated, b'" in line for line in failed), out
    assert len(failed) == len(failing), out
