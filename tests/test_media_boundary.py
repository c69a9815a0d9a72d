"""Next-event estimation through null interfaces: a shadow ray from inside a bounded medium (or from a
surface behind it) to a point on an area emitter must arrive with the medium's transmittance over the
chord it crosses, never be blocked by the emitter's own surface.

The check is deterministic and analytic: for a null-BSDF cube holding a homogeneous medium, the
transmittance of the segment p -> q is exp(-sigma_t * chord), with the chord the length of the segment
inside the cube (slab intersection in the cube's object space). Points p inside the cube and on a
wall behind it, points q on a rectangle light outside it, at short range and grazing, as in
``scenes/medium-cube.xml`` and ``scenes/test/medium-room.xml``.

On the code before the fix (the ray kept its first direction after the crossing and shortened its
length by the hit distance only), 23 and 27 of 2000 segments from the medium cube's interior
(rotated 30 degrees and not) and 248 of 2491 from the medium room's back wall came back 0 (blocked
by the light itself); the expected count
of such failures is 0 here, so the tests assert exactly 0 up to 1e-6 absolute: each crossing pushes
the ray's origin ~1e-7 off the surface (offset_origin), which changes the chord by < 1e-6 and the
transmittance by less than that (sigma_t <= 2.5, transmittance <= 1); a blocked ray is off by the
whole transmittance (> 0.001 for every segment drawn here).
"""
from pathlib import Path

import numpy as np
import pytest

from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.integrators.path.volume import shadow_transmittance
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load

ROOT = Path(__file__).resolve().parents[1]


def _chord(minv, p, q):
    """Length of the segment p -> q inside the cube [-1, 1]^3 mapped by the inverse to_world minv."""
    a = (minv @ np.r_[p, 1.0])[:3]
    d = (minv @ np.r_[q, 1.0])[:3] - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-1.0 - a) / d, (1.0 - a) / d
    lo = max(np.nanmax(np.minimum(t1, t2)), 0.0)
    hi = min(np.nanmin(np.maximum(t1, t2)), 1.0)
    return max(hi - lo, 0.0) * float(np.linalg.norm(np.subtract(q, p)))


def _setup(rel, **defaults):
    scene = load(ROOT / rel, res=8, **defaults)
    sa = compile_scene(scene)
    cube = next(s for s in scene.shapes if s.type == "cube")
    lights = [s for s in scene.shapes if s.emitter is not None]
    return scene, sa, cube, lights


@pytest.mark.parametrize("angle", [0, 30])
def test_shadow_rays_from_inside_the_medium_cube_reach_the_light(angle):
    scene, sa, cube, (light,) = _setup("scenes/medium-cube.xml", angle=angle)
    minv = np.linalg.inv(cube.to_world)
    sigma = float(sa.media[0][0])
    stack = np.empty(STACK_SIZE, np.int32)
    rng = np.random.default_rng(5)
    wrong = []
    for _ in range(2000):
        p = (cube.to_world @ np.r_[rng.uniform(-0.999, 0.999, 3), 1.0])[:3]
        q = (light.to_world @ np.r_[rng.uniform(-1, 1, 2), 0.0, 1.0])[:3]
        want = np.exp(-sigma * _chord(minv, p, q))
        got = shadow_transmittance(sa, tuple(p), (0.0, 0.0, 0.0), tuple(q), 0, stack)
        if not np.allclose(got, want, rtol=0, atol=1e-6):
            wrong.append((tuple(p), tuple(q), got[0], want))
    assert not wrong, f"{len(wrong)} of 2000 shadow rays wrong, e.g. {wrong[:2]}"


def test_shadow_rays_crossing_the_medium_twice_reach_the_light():
    """From the back wall outside the medium room's cube, through two of its faces, to the outside
    light (both ends in vacuum). Segments the floor blocks are skipped (the floor is not null)."""
    scene, sa, cube, lights = _setup("scenes/test/medium-room.xml")
    light = next(s for s in lights if s.id == "light")
    wall = next(s for s in scene.shapes if s.id == "back-wall")
    minv = np.linalg.inv(cube.to_world)
    sigma = float(sa.media[0][0])
    stack = np.empty(STACK_SIZE, np.int32)
    rng = np.random.default_rng(6)
    checked, wrong = 0, []
    for _ in range(3000):
        p = (wall.to_world @ np.r_[rng.uniform(-0.6, 0.6, 2), 0.0, 1.0])[:3]
        q = (light.to_world @ np.r_[rng.uniform(-1, 1, 2), 0.0, 1.0])[:3]
        if min(p[1], q[1]) < -1.2:          # the floor (y = -1.2) is between: a genuine blocker
            continue
        checked += 1
        want = np.exp(-sigma * _chord(minv, p, q))
        got = shadow_transmittance(sa, tuple(p), (0.0, 0.0, 1.0), tuple(q), -1, stack)
        if not np.allclose(got, want, rtol=0, atol=1e-6):
            wrong.append((tuple(p), tuple(q), got[0], want))
    assert checked > 1500
    assert not wrong, f"{len(wrong)} of {checked} shadow rays wrong, e.g. {wrong[:2]}"


def test_emitting_shape_without_bsdf_is_black_as_in_mitsuba():
    """Mitsuba 3 gives a shape that carries an area emitter and no bsdf a diffuse BSDF of reflectance
    0 (``mi.traverse`` of scenes/medium-cube.xml: light.bsdf.reflectance.value = 0); any other shape
    without a bsdf gets diffuse 0.5."""
    scene = load(ROOT / "scenes/medium-cube.xml", res=8)
    light = next(s for s in scene.shapes if s.emitter is not None)
    floor = next(s for s in scene.shapes if s.id == "floor")
    assert light.bsdf.type == "diffuse" and np.all(np.asarray(light.bsdf.reflectance) == 0.0)
    assert floor.bsdf.type == "diffuse"
