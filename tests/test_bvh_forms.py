"""The BVH's form (kernels.accel.forms): a one-leaf scene's node table is read-only, and the
traversals compiled for it test the leaf alone -- with the hits of the code for any tree."""
import math
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gdlearn.kernels.accel.bvh import STACK_SIZE, any_hit, closest_hit
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load

ROOT = Path(__file__).resolve().parents[1]


def _scene(name):
    return compile_scene(load(ROOT / "scenes" / f"{name}.xml", res=8))


def test_only_a_one_leaf_tree_gets_the_read_only_table():
    assert not _scene("cornell-box").node_info.flags.writeable
    assert not _scene("volume-caustic").node_info.flags.writeable
    mesh = _scene("mesh")
    assert mesh.node_info[0, 1] == 0 and mesh.node_info.flags.writeable      # a tree


# (node_info writable, materials writable): between them both flags are read-only and writable once
@pytest.mark.parametrize("name, flags", [("cornell-box", (False, False)), ("mesh", (True, False)),
                                         ("glossy-box", (False, True))])
def test_a_pickled_scene_keeps_the_forms_it_compiles_for(name, flags):
    """numpy unpickles arrays writable; SceneArrays puts the write flags back, since they name what
    the kernels compile (the BVH's form, the material table's tier), and the arrays themselves."""
    sa = _scene(name)
    back = pickle.loads(pickle.dumps(sa))
    assert type(back) is type(sa)
    for field, a, b in zip(sa._fields, sa, back):
        if isinstance(a, np.ndarray):
            assert b.flags.writeable == a.flags.writeable, field
            assert b.flags.f_contiguous == a.flags.f_contiguous, field       # the tier's memory order
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b, field
    assert (sa.node_info.flags.writeable, sa.materials.flags.writeable) == flags


@pytest.mark.parametrize("name", ["cornell-box", "volume-caustic"])
def test_the_leaf_code_finds_the_hits_of_the_code_for_any_tree(name):
    """Random rays inside the scene's bounds, through both forms of the same table: the same
    closest hit (prim, t, u, v) and the same any-hit answer, with and without skipping null
    interfaces (the volume caustic's block of fog is bounded by a null BSDF)."""
    sa = _scene(name)
    leaf_form = sa.node_info
    tree_form = leaf_form.copy()                 # writable: compiled as any tree
    assert tree_form.flags.writeable
    stack = np.empty(STACK_SIZE, np.int32)
    rng = np.random.default_rng(3)
    c, r = sa.bsphere[:3], sa.bsphere[3]
    hits = 0
    for _ in range(3000):
        o = tuple(c + rng.uniform(-0.9, 0.9, 3) * r / math.sqrt(3))
        d = rng.normal(size=3)
        d = tuple(d / np.linalg.norm(d))
        tmax = rng.choice([math.inf, 0.5 * r])
        a = closest_hit(sa.nodes, leaf_form, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        b = closest_hit(sa.nodes, tree_form, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack)
        assert a == b
        hits += a[1] >= 0
        for skip in (False, True):
            assert (any_hit(sa.nodes, leaf_form, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack, skip, sa.materials)
                    == any_hit(sa.nodes, tree_form, sa.prims, sa.prim_info, o, d, 0.0, tmax, stack, skip,
                               sa.materials))
    assert hits > 1000          # the rays found surfaces, not only misses


_PROBE = r"""
import numpy as np, math
from numba import njit
from gdlearn.kernels.accel import bvh
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load
sa = compile_scene(load(%r, res=8))

@njit
def probe(sa, stack):
    return bvh.closest_hit_inline(sa.nodes, sa.node_info, sa.prims, sa.prim_info, (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 1.0), 0.0, math.inf, stack)

probe(sa, np.empty(bvh.STACK_SIZE, np.int32))
print(len(bvh._closest_hit_leaf.signatures), len(bvh._closest_hit_tree.signatures))
"""


@pytest.mark.parametrize("name, compiled", [("cornell-box", "1 0"), ("mesh", "0 1")])
def test_a_one_leaf_scene_compiles_no_tree_traversal(name, compiled):
    """In a fresh process, a kernel calling ``closest_hit_inline`` on the scene's table types the
    leaf's code alone for a one-leaf scene, the code for any tree for a tree (a dispatcher typed
    from numba's cache still counts its signature)."""
    out = subprocess.run([sys.executable, "-c", _PROBE % str(ROOT / "scenes" / f"{name}.xml")], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    assert out.split("\n")[-2] == compiled
