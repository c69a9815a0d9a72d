"""pathclass against a plain-Python reference written from the class definitions (Heckbert strings):
every vertex-class string up to length 6, and reachability by brute force over extensions."""
from __future__ import annotations

import itertools
import re

import numpy as np
import pytest

from gdlearn.kernels import layout
from gdlearn.kernels import pathclass as pc

CODE = {"D": layout.V_DIFFUSE, "G": layout.V_GLOSSY, "S": layout.V_SPECULAR, "M": layout.V_MEDIUM}
NAMES = ["emission", "direct-lighting", "diffuse-interreflection", "glossy", "specular", "caustics",
         "single-scattering", "multiple-scattering", "volume-caustics"]


def reference_class(path: str) -> int:
    """``path`` lists interior vertices from the camera to the light, e.g. "DS" = E D S L.
    Written independently of the kernel: regular expressions on the light-to-eye string."""
    from_light = path[::-1]
    n = len(path)
    if n == 0:
        return NAMES.index("emission")
    if n == 1:
        return NAMES.index("single-scattering" if path == "M" else "direct-lighting")
    if re.match(r"^S+[DG]", from_light):
        return NAMES.index("caustics")
    if re.match(r"^S+M", from_light):
        return NAMES.index("volume-caustics")
    if "M" in path:
        return NAMES.index("multiple-scattering")
    if "S" in path:
        return NAMES.index("specular")
    if "G" in path:
        return NAMES.index("glossy")
    assert set(path) == {"D"}
    return NAMES.index("diffuse-interreflection")


def strings(max_len):
    for n in range(max_len + 1):
        for t in itertools.product("DGSM", repeat=n):
            yield "".join(t)


def state_of(path):
    s = pc.pc_init()
    for ch in path:
        s = pc.pc_push(s, CODE[ch])
    return s


def test_names_and_bits_agree():
    assert list(pc.CLASS_NAMES) == NAMES and pc.N_CLASSES == 9 and pc.ALL_MASK == 511


def test_every_string_up_to_6_has_the_reference_class():
    bad = [(p, pc.pc_class(state_of(p)), reference_class(p)) for p in strings(6)
           if pc.pc_class(state_of(p)) != reference_class(p)]
    assert not bad, bad[:10]


def test_each_class_occurs():
    assert {reference_class(p) for p in strings(4)} == set(range(9))


# Brute force: every class reachable from a prefix is reached with at most 2 more vertices (see
# pc_reachable's docstring); extending by up to 3 checks that claim rather than assuming it.
EXT = 3


def brute_reachable(prefix):
    return {reference_class(prefix + e) for e in strings(EXT)}


@pytest.fixture(scope="module")
def reach_table():
    return {p: brute_reachable(p) for p in strings(6)}


def test_reachable_single_class_masks(reach_table):
    bad = []
    for p, reach in reach_table.items():
        s = state_of(p)
        for c in range(9):
            if pc.pc_reachable(s, 1 << c) != (c in reach):
                bad.append((p, NAMES[c]))
    assert not bad, bad[:10]


def test_reachable_random_masks(reach_table):
    rng = np.random.default_rng(7)
    masks = [int(m) for m in rng.integers(0, 512, size=40)] + [0, 511]
    for p, reach in reach_table.items():
        s = state_of(p)
        rbits = sum(1 << c for c in reach)
        for m in masks:
            assert pc.pc_reachable(s, m) == bool(rbits & m), (p, m)


def test_max_interior_against_brute_force():
    longest = {c: 0 for c in range(9)}
    unbounded = set()
    for p in strings(6):
        c = reference_class(p)
        longest[c] = max(longest[c], len(p))
        if len(p) == 6:
            unbounded.add(c)        # still occurring at the longest length tried: unbounded
    for m in range(512):
        cls = [c for c in range(9) if (m >> c) & 1]
        want = -1 if any(c in unbounded for c in cls) else max([longest[c] for c in cls], default=0)
        assert pc.pc_max_interior(m) == want, m


def test_counts_saturate_and_stay_classifiable():
    s = pc.pc_init()
    for _ in range(70000):
        s = pc.pc_push(s, layout.V_SPECULAR)
    s2 = pc.pc_push(s, layout.V_DIFFUSE)
    assert pc.pc_class(s) == NAMES.index("specular")           # all specular: no caustic
    assert pc.pc_class(pc.pc_push(s2, layout.V_SPECULAR)) == NAMES.index("caustics")
    assert s > 0 and s2 > 0


def test_usable_inside_njit_with_int32_vertex_classes():
    """The tracer calls these from numba with vertex classes read from int32 arrays."""
    from numba import njit

    @njit(cache=False)
    def trace(vcs, mask):
        s = pc.pc_init()
        out = np.empty(len(vcs), dtype=np.int64)
        for i in range(len(vcs)):
            s = pc.pc_push(s, vcs[i])
            out[i] = pc.pc_class(s) if pc.pc_reachable(s, mask) else -1
        return out, pc.pc_max_interior(mask)

    vcs = np.array([CODE[c] for c in "DSSM"], dtype=np.int32)
    got, bound = trace(vcs, pc.ALL_MASK)
    assert [int(g) for g in got] == [reference_class(p) for p in ("D", "DS", "DSS", "DSSM")]
    assert bound == -1
    got, bound = trace(vcs, 0b11)          # "direct": the prefix dies after its first vertex
    assert int(got[0]) == 1 and int(got[1]) == -1 and bound == 1


# The camera's end (pathclass.MEDIA_TRANSPORT, SURFACE_TRANSPORT): paths whose first non-specular
# vertex from the camera is a medium event, and the others. The reference reads the string from the
# camera end, independently of the kernel's incremental state.
def reference_eye_medium(path: str) -> bool:
    rest = path.lstrip("S")
    return rest[:1] == "M"


def reference_wanted(path: str, mask: int) -> bool:
    if not (mask >> reference_class(path)) & 1:
        return False
    if mask & pc.MEDIA_TRANSPORT:
        return reference_eye_medium(path)
    if mask & pc.SURFACE_TRANSPORT:
        return not reference_eye_medium(path)
    return True


def test_eye_kind_is_the_first_non_specular_camera_vertex():
    kinds = {"": pc.EYE_NONE, "D": pc.EYE_SURFACE, "G": pc.EYE_SURFACE, "M": pc.EYE_MEDIUM}
    bad = [p for p in strings(6) if pc.pc_eye(state_of(p)) != kinds[p.lstrip("S")[:1]]]
    assert not bad, bad[:10]


@pytest.mark.parametrize("end", ["MEDIA_TRANSPORT", "SURFACE_TRANSPORT"])
def test_wanted_and_reachable_with_a_camera_end(end):
    """pc_wanted is the reference's, and pc_reachable is exact: true iff some extension by up to
    EXT vertices is wanted, for every prefix up to 6 vertices and class masks with the end bit."""
    bit = getattr(pc, end)
    rng = np.random.default_rng(11)
    masks = [bit | (1 << c) for c in range(9)] + [bit | int(m) for m in rng.integers(1, 512, size=12)] + [bit | 511]
    bad = []
    for p in strings(6):
        s = state_of(p)
        for m in masks:
            if pc.pc_wanted(s, m) != reference_wanted(p, m):
                bad.append(("wanted", p, m))
            if pc.pc_reachable(s, m) != any(reference_wanted(p + e, m) for e in strings(EXT)):
                bad.append(("reachable", p, m))
    assert not bad, bad[:10]


def test_the_two_camera_ends_partition_every_path():
    for p in strings(5):
        s = state_of(p)
        assert pc.pc_wanted(s, pc.ALL_MASK | pc.MEDIA_TRANSPORT) != pc.pc_wanted(s, pc.ALL_MASK | pc.SURFACE_TRANSPORT)
        assert pc.pc_wanted(s, pc.ALL_MASK)
