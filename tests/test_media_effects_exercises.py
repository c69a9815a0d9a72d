"""The exercises of the chapters "Participating media and volumetric path tracing" (free-flight) and
"The effects a scene calls for" (heckbert-classes) catch the plausible wrong answers.

free-flight: -log(1 - u) instead of log1p (thin media lose digits), a spectral weight divided by the
picked channel's density alone (biased), and a pass weight of 1 whatever the channels (biased).
heckbert-classes: caustics read from the eye end (L ... S+ D E, the classic reversal), and a
specular class that forgets to exclude caustics (two classes match). Each wrong stub must fail its
`gdlearn check` (run in a child process on a copy of the exercise, with readable feedback), while
the reference solution passes.
"""
from pathlib import Path

import pytest

from conftest import check_exercise_source

ROOT = Path(__file__).resolve().parent.parent
EX = ROOT / "exercises"


FREE = (EX / "_solutions" / "free_flight.py").read_text()
HECK = (EX / "_solutions" / "heckbert_classes.py").read_text()
FREE_WRONG = {
    "log(1 - u)": FREE.replace("-math.log1p(-u)", "-math.log(1.0 - u)"),
    "picked channel's pdf only": FREE.replace("pdf = sum(s * x for s, x in zip(sigma_t, tr)) / 3.0",
                                              "pdf = sigma_t[c] * tr[c]"),
    "pass weight 1": FREE.replace("return t_max, False, tuple(x / p for x in tr)",
                                  "return t_max, False, (1.0, 1.0, 1.0)"),
}
HECK_WRONG = {
    "caustics read from the eye end": HECK.replace('"caustics": r"LS+[DG][DGSM]*E"',
                                                   '"caustics": r"L[DGSM]*[DG]S+E"'),
    "specular does not exclude caustics": HECK.replace(
        '"specular": r"L(?:S{2,}|[DG][DGS]*S[DGS]*)E"', '"specular": r"L(?=[DGS]*S)[DGS]{2,}E"'),
}
for label, src in {**FREE_WRONG, **HECK_WRONG}.items():
    assert src not in (FREE, HECK), f"the planted mistake {label!r} did not change the solution"

CASES = ([("free-flight", "solution", FREE, True)]
         + [("free-flight", k, v, False) for k, v in FREE_WRONG.items()]
         + [("heckbert-classes", "solution", HECK, True)]
         + [("heckbert-classes", k, v, False) for k, v in HECK_WRONG.items()])


@pytest.mark.parametrize("name, label, source, right", CASES, ids=[f"{c[0]}: {c[1]}" for c in CASES])
def test_the_checks_separate_right_from_wrong(tmp_path, name, label, source, right):
    rc, out = check_exercise_source(tmp_path, name, source)
    if right:
        assert rc == 0, out
    else:
        assert rc == 1 and "FAIL" in out, f"the wrong answer {label!r} passes every check:\n{out}"
        assert "Traceback" not in out, out
