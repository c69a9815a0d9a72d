"""Scenes get kernels compiled without the BSDF families they do not have
(gdlearn.kernels.bsdf.tiers: the material table's tier, named by its write flag and memory
order), and those kernels render the image of the full ones bit for bit.

A lean, smooth or glossy kernel runs the same code as the full one on its families, so any
difference is a bug: a family left out that the scene has (its surfaces would turn black),
or a tier's branch that differs from the full one.
"""
from pathlib import Path

import numba
import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.kernels import layout as L
from gdlearn.kernels.bsdf.tiers import table_tier, tiered_table
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted(p.stem for p in (ROOT / "scenes").glob("*.xml"))


def _expected_tier(types):
    """The rule, written from the BSDF type names (not from the code's constants)."""
    if types <= {"diffuse", "null"}:
        return "lean"
    if types <= {"diffuse", "null", "conductor", "dielectric"}:
        return "smooth"
    if types <= {"diffuse", "null", "roughconductor", "roughplastic"}:
        return "glossy"
    return "all"


@pytest.mark.parametrize("name", SCENES)
def test_the_table_form_follows_the_scene_files_bsdf_types(name):
    """Read from the scene file's BSDF types: lean = read-only row-major, smooth = read-only
    column-major, glossy = writable column-major, every other scene a writable row-major table."""
    scene = load(ROOT / "scenes" / f"{name}.xml", res=4)
    types = {b.type for b in _bsdfs(scene)}
    sa = compile_scene(scene)
    tier = _expected_tier(types)
    assert sa.materials.flags.writeable == (tier in ("glossy", "all")), types
    assert (tier in ("smooth", "glossy")) == (not sa.materials.flags.c_contiguous), types
    # what numba sees: a row's layout and write flag, which tiers.tier_of reads
    row = numba.typeof(sa.materials[0])
    assert (row.mutable, row.layout) == {"lean": (False, "C"), "smooth": (False, "A"), "glossy": (True, "A"),
                                         "all": (True, "C")}[tier]


def test_every_tier_is_met_by_a_shipped_scene():
    """Else the image tests below would not cover it. (The full tier is what they compare with.)"""
    tiers = {_expected_tier({b.type for b in _bsdfs(load(ROOT / "scenes" / f"{n}.xml", res=4))}) for n in SCENES}
    assert tiers == {"lean", "smooth", "glossy"}


def test_a_one_row_table_outside_the_lean_tier_gets_every_family():
    """A column-major table of one row is row-major too: read-only it would be typed lean and a
    dielectric would render black. It is given the full tier instead."""
    row = np.zeros((1, L.MAT_WIDTH))
    row[0, L.MAT_TYPE] = L.DIELECTRIC
    assert table_tier(row) == "all"
    assert tiered_table(row).flags.writeable
    row[0, L.MAT_TYPE] = L.ROUGHCONDUCTOR
    assert table_tier(row) == "all"
    two = np.zeros((2, L.MAT_WIDTH))
    two[:, L.MAT_TYPE] = (L.DIELECTRIC, L.DIFFUSE)
    assert table_tier(two) == "smooth"
    assert numba.typeof(tiered_table(two)[0]).layout == "A"
    two[:, L.MAT_TYPE] = (L.ROUGHPLASTIC, L.DIFFUSE)
    assert table_tier(two) == "glossy"
    assert numba.typeof(tiered_table(two)[0]) == numba.types.Array(numba.float64, 1, "A")    # writable
    two[:, L.MAT_TYPE] = (L.ROUGHPLASTIC, L.DIELECTRIC)       # glossy and smooth families: every one
    assert table_tier(two) == "all"


def _bsdfs(scene):
    return [s.bsdf for s in scene.shapes if s.bsdf is not None]


def _full(sa):
    """The same scene with a writable row-major table: numba compiles the kernels with every family."""
    return sa._replace(materials=np.array(sa.materials, order="C"))     # a copy: writable


# a smooth pair per integrator kind: glass on diffuse (the close-up), glass in a medium, mirrors;
# the glossy box's rough metal and rough plastic (glossy tier) in each of them
@pytest.mark.parametrize("integrator, name", [("pt", "cornell-box"), ("pt", "medium-cube"),
                                              ("pt", "glossy-box"), ("gpt", "glossy-box"),
                                              ("gpt-replay", "glossy-box"),
                                              ("gpt", "cornell-box"), ("pt", "fog-box"),
                                              ("pt", "caustic-closeup"), ("gpt", "caustic-closeup"),
                                              ("pt", "volume-caustic"), ("gpt", "caustics-box"),
                                              ("gpt-replay", "mirror-caustic")])
def test_tiered_kernels_render_the_full_kernels_image(integrator, name):
    scene = load(ROOT / "scenes" / f"{name}.xml", res=10)
    sa = compile_scene(scene)
    assert not sa.materials.flags.c_contiguous or not sa.materials.flags.writeable    # not the full tier
    a = make(integrator, scene, seed=2, spp_per_pass=2, sa=sa).render_pass(1).images
    b = make(integrator, scene, seed=2, spp_per_pass=2, sa=_full(sa)).render_pass(1).images
    assert a["primal"].mean() > 0
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_a_rough_dielectric_keeps_every_family():
    scene = load(ROOT / "scenes" / "glossy-box.xml", res=4)
    assert table_tier(compile_scene(scene).materials) == "glossy"
    for shape in scene.shapes:
        if shape.bsdf is not None and shape.bsdf.type == "roughconductor":
            shape.bsdf.type = "roughdielectric"
    sa = compile_scene(scene)
    assert sa.materials.flags.writeable and sa.materials.flags.c_contiguous
