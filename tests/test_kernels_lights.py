"""Shadow rays towards emitters at infinity (directional, constant): their length follows Mitsuba 3's
``directional.cpp`` / ``constant.cpp``, 2 max(r, |p - c|) for the scene's bounding sphere (c, r).

A fixed 2 r (gdlearn's rule before) ends the ray early from a point outside the sphere; in a global
medium such points are common (camera rays scatter anywhere along their way) and kept up to 24 %
too much transmittance: the fuzzer's seed 0 (tests/test_refs_fuzz.py) against Mitsuba found it.
"""
import math

import numpy as np
import pytest

from gdlearn.kernels.lights import infinite_distance, same_direction_point, sample_emitter
from gdlearn.scene.compile import compile_scene
from gdlearn.scene.load import load

SCENE = """<scene version="3.0.0">
  <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>
  <shape type="rectangle"><transform name="to_world"><translate value="1, 2, 3"/></transform></shape>
  <emitter type="{kind}">{params}</emitter>
</scene>"""
PARAMS = {"directional": '<vector name="direction" value="0, -1, 0"/><rgb name="irradiance" value="1"/>',
          "constant": '<rgb name="radiance" value="1"/>'}


def _arrays(tmp_path, kind):
    f = tmp_path / "s.xml"
    f.write_text(SCENE.format(kind=kind, params=PARAMS[kind]))
    return compile_scene(load(str(f)))


@pytest.mark.parametrize("kind", ["directional", "constant"])
def test_shadow_ray_leaves_the_bounding_sphere_from_inside_and_outside(tmp_path, kind):
    sa = _arrays(tmp_path, kind)
    c, r = sa.bsphere[:3], sa.bsphere[3]
    assert np.allclose(c, (1, 2, 3)) and r == pytest.approx(math.sqrt(2))   # the unit rectangle
    for p, want in [((1.0, 2.0, 3.0), 2 * r),                     # the centre: 2 r
                    ((1.5, 2.0, 3.0), 2 * r),                     # inside
                    ((1.0, 2.0, 13.0), 2 * 10.0),                 # 10 away: 2 |p - c|
                    ((-20.0, 2.0, 3.0), 2 * 21.0)]:
        assert infinite_distance(sa.emitters, 0, p) == pytest.approx(want, rel=1e-12)
        em, q, _, d, dist, w, _, _, _ = sample_emitter(sa.emitters, sa.em_prims, sa.em_cdf, sa.prims,
                                                       sa.prim_info, p, 0.3, 0.4, 0.7)
        assert em == 0 and dist == pytest.approx(want, rel=1e-12)
        assert np.allclose(np.subtract(q, p), np.multiply(d, want), rtol=1e-12, atol=1e-12)
        # the far end lies outside the bounding sphere, wherever p is
        assert np.linalg.norm(np.subtract(q, c)) >= r * (1 - 1e-12)


def test_a_shifted_point_gets_its_own_length_along_the_base_direction(tmp_path):
    sa = _arrays(tmp_path, "directional")
    p_base = (1.0, 2.0, 3.0)
    _, q_base, _, d, _, _, _, _, _ = sample_emitter(sa.emitters, sa.em_prims, sa.em_cdf, sa.prims,
                                                    sa.prim_info, p_base, 0.5, 0.5, 0.5)
    p = (1.0, 2.0, 23.0)                     # an offset vertex 20 away from the centre
    q = same_direction_point(sa.emitters, 0, p_base, q_base, p)
    assert np.allclose(np.subtract(q, p), np.multiply(d, 40.0), rtol=1e-12)
    assert np.allclose(d, (0, 1, 0))         # towards the light: -direction
