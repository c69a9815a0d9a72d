"""Scenes of diffuse and null materials only get kernels compiled without the other BSDF families
(gdlearn.kernels.bsdf.dispatch: a read-only material table), and those kernels render the image
of the full ones bit for bit.

The lean and the full kernel run the same diffuse and null code in the same order, so any
difference is a bug: a family left out that the scene has (its surfaces would turn black), or a
lean branch that differs from the full one.
"""
from pathlib import Path

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted(p.stem for p in (ROOT / "scenes").glob("*.xml"))


@pytest.mark.parametrize("name", SCENES)
def test_the_table_is_read_only_exactly_when_every_bsdf_is_diffuse_or_null(name):
    """The rule, read from the scene file's BSDF types (not from the table the code built)."""
    scene = load(ROOT / "scenes" / f"{name}.xml", res=4)
    types = {b.type for b in _bsdfs(scene)}
    sa = compile_scene(scene)
    assert sa.materials.flags.writeable == (not types <= {"diffuse", "null"}), types


def _bsdfs(scene):
    return [s.bsdf for s in scene.shapes if s.bsdf is not None]


def _full(sa):
    """The same scene with a writable table: numba compiles the kernels with every family."""
    return sa._replace(materials=np.array(sa.materials))


@pytest.mark.parametrize("integrator, name", [("pt", "cornell-box"), ("pt", "medium-cube"),
                                              ("gpt", "cornell-box"), ("pt", "fog-box")])
def test_lean_kernels_render_the_full_kernels_image(integrator, name):
    scene = load(ROOT / "scenes" / f"{name}.xml", res=10)
    sa = compile_scene(scene)
    assert not sa.materials.flags.writeable
    a = make(integrator, scene, seed=2, spp_per_pass=2, sa=sa).render_pass(1).images
    b = make(integrator, scene, seed=2, spp_per_pass=2, sa=_full(sa)).render_pass(1).images
    assert a["primal"].mean() > 0
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_a_scene_with_glass_keeps_every_family():
    sa = compile_scene(load(ROOT / "scenes" / "volume-caustic.xml", res=4))
    assert sa.materials.flags.writeable
