"""Tests of the exercise "heckbert-classes". Each docstring is the line `gdlearn check` prints.

The reference is gdlearn's own classifier, ``gdlearn.kernels.pathclass``: the path tracer pushes
the interior vertices from the camera towards the light and asks ``pc_class`` for the class.
"""
import itertools
import re

from gdlearn.kernels import layout
from gdlearn.kernels import pathclass as pc
from gdlearn.teaching.exercises import load_target

ex = load_target("heckbert-classes")
CODE = {"D": layout.V_DIFFUSE, "G": layout.V_GLOSSY, "S": layout.V_SPECULAR, "M": layout.V_MEDIUM}


def gdlearn_class(path: str) -> str:
    """gdlearn's class of the Heckbert string ``path`` = "L ... E" (pushed from the eye end)."""
    s = pc.pc_init()
    for ch in reversed(path[1:-1]):
        s = pc.pc_push(s, CODE[ch])
    return pc.CLASS_NAMES[pc.pc_class(s)]


def all_paths(max_interior=6):
    for n in range(max_interior + 1):
        for t in itertools.product("DGSM", repeat=n):
            yield "L" + "".join(t) + "E"


def test_hand_examples():
    """classify: LE, LDE, LME, LDDE, LSDE, LSME, LDSE, LGDE, LMDE on hand"""
    cases = {"LE": "emission", "LDE": "direct-lighting", "LSE": "direct-lighting", "LME": "single-scattering",
             "LDDE": "diffuse-interreflection", "LSDE": "caustics", "LSSGE": "caustics",
             "LSME": "volume-caustics", "LDSE": "specular", "LSSE": "specular", "LGDE": "glossy",
             "LMDE": "multiple-scattering", "LDME": "multiple-scattering"}
    for path, want in cases.items():
        got = ex.classify(path)
        assert got == want, f"{path}: expected {want}, got {got}"


def test_every_expression_is_valid():
    """class_regex: a valid regular expression for each of the nine classes"""
    for name in pc.CLASS_NAMES:
        rx = ex.class_regex(name)
        try:
            re.compile(rx)
        except re.error as err:
            raise AssertionError(f"class_regex({name!r}) = {rx!r} does not compile: {err}") from None


def test_expressions_partition_all_paths():
    """class_regex: every path with up to 6 vertices matches exactly one of the nine expressions"""
    rx = {n: re.compile(ex.class_regex(n)) for n in pc.CLASS_NAMES}
    for path in all_paths():
        hits = [n for n, r in rx.items() if r.fullmatch(path)]
        assert len(hits) == 1, f"{path} matches {len(hits)} classes ({', '.join(hits) or 'none'}), not exactly one"


def test_expressions_agree_with_gdlearn():
    """class_regex: the class each path matches is the one gdlearn's path tracer assigns"""
    rx = {n: re.compile(ex.class_regex(n)) for n in pc.CLASS_NAMES}
    for path in all_paths():
        hits = [n for n, r in rx.items() if r.fullmatch(path)]
        want = gdlearn_class(path)
        assert hits == [want], f"{path}: gdlearn says {want}, your expressions say {', '.join(hits) or 'none'}"


def test_classify_agrees_with_gdlearn():
    """classify: the class of every path with up to 5 vertices is gdlearn's"""
    for path in all_paths(5):
        got, want = ex.classify(path), gdlearn_class(path)
        assert got == want, f"{path}: expected {want}, got {got}"
