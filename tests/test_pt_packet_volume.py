"""The volume packet path tracer (gdlearn.integrators.path.packet_volume) renders volpath's image bit
for bit, for every scene it accepts, and refuses the others.

Exact comparisons, as in tests/test_pt_packet.py: a lane runs radiance_volpath's segments with the
same functions, random numbers and order of operations on its radiance, so any difference is a bug
(a next-event term added with the wrong throughput, a transmittance over the wrong segment, a null
interface crossed twice, a random number of another segment).
"""
import os
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from test_pt_packet import _pair  # noqa: E402  (scalar image, packet image, their stats) of one pass

from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["fog-box", "medium-cube", "spot-medium", "volume-caustic", "test/medium-room",
                                  "test/single-scatter"])
def test_media_null_interfaces_glass_and_spot_lights_bit_for_bit(name):
    """The fog box (a medium everywhere, the camera in it), media held by null-BSDF cubes (shadow
    rays that cross interfaces finish their march lane by lane), a spot light, a glass sphere
    focusing light into a medium."""
    scene = load(ROOT / "scenes" / f"{name}.xml", res=14)
    a, b, sa, sb = _pair(scene, spp=3)
    assert a.mean() > 0 and np.array_equal(a, b) and sa == sb


@pytest.mark.parametrize("max_depth", [1, 2, 3, -1])
def test_depths_seeds_and_threads(max_depth):
    scene = load(ROOT / "scenes" / "spot-medium.xml", res=12)
    a, b, _, _ = _pair(scene, seed=9, spp=2, pass_index=3, threads=2, max_depth=max_depth)
    assert np.array_equal(a, b)


def test_a_transport_split_or_a_subset_renders_one_path_at_a_time():
    scene = load(ROOT / "scenes" / "fog-box.xml", res=8)
    for kw in ({"transport": "media"}, {"effects": "single-scattering"}):
        assert not make("pt", scene, **kw).packets
        with pytest.raises(ValueError, match="packets"):
            make("pt", scene, packets=True, **kw)
