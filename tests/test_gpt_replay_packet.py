"""gpt-replay on the packet tracer (gdlearn.integrators.path.gpt_replay_packet) gives the one-path
kernel's five buffers and counters bit for bit.

Exact comparisons, as in tests/test_pt_packet.py: every path is radiance_path's and every sum runs
over the samples in their order, so any difference is a bug (an offset with the wrong key or film
position, a skipped or doubled shift, a roulette decision on another random number, a sum out of
order).
"""
import os
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
from _pt_scenes import cornell_box  # noqa: E402

from gdlearn.integrators import make  # noqa: E402
from gdlearn.scene.load import load  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _pair(scene, spp, sample0=0, **kw):
    a = make("gpt-replay", scene, seed=3, packets=False, **kw)
    b = make("gpt-replay", scene, seed=3, **kw)
    assert b.packets and not a.packets
    (oa, ca, _), (ob, cb, _) = a.trace(sample0, spp), b.trace(sample0, spp)
    return oa, ob, ca, cb


@pytest.mark.parametrize("name", ["cornell-box", "glossy-box", "caustics-box"])
def test_buffers_and_counters_bit_for_bit(name):
    scene = cornell_box(res=12) if name == "cornell-box" else load(ROOT / "scenes" / f"{name}.xml", res=12)
    oa, ob, ca, cb = _pair(scene, spp=3, sample0=5, threads=2)
    assert np.abs(oa[1:]).sum() > 0 and np.array_equal(oa, ob) and ca == cb


def test_shift_roulette_and_more_samples_than_a_chunk():
    """The shift roulette (its decisions need the base's value) and 1100 samples a pixel: the row's
    bases go through the packet tracer in chunks of 1024 (gpt_replay_packet.CHUNK)."""
    oa, ob, ca, cb = _pair(cornell_box(res=4), spp=1100, shift_rr=0.5, shift_rr_min=0.2, threads=1)
    assert ca["shifts_rr_skipped"] > 0 and ca["shifts_outside"] > 0
    assert np.array_equal(oa, ob) and ca == cb


@pytest.mark.parametrize("name", ["fog-box", "spot-medium", "volume-caustic"])
def test_media_bit_for_bit(name):
    """With media the offsets go through the volume packet tracer (packet_volume): the fog box (the
    camera in the medium), a medium behind null interfaces lit by a spot light, a glass sphere's
    volume caustic."""
    scene = load(ROOT / "scenes" / f"{name}.xml", res=10)
    oa, ob, ca, cb = _pair(scene, spp=2, sample0=1, threads=2)
    assert np.abs(oa[1:]).sum() > 0 and np.array_equal(oa, ob) and ca == cb


def test_media_shift_roulette_over_chunks():
    oa, ob, ca, cb = _pair(load(ROOT / "scenes" / "fog-box.xml", res=3), spp=1100, shift_rr=0.5, shift_rr_min=0.2,
                           threads=1)
    assert ca["shifts_rr_skipped"] > 0 and np.array_equal(oa, ob) and ca == cb


def test_diagnostics_trace_one_path_at_a_time_and_ineligible_scenes_refuse_packets():
    integ = make("gpt-replay", cornell_box(res=6), seed=0)
    assert integ.packets
    maps = integ.decorrelation(spp=2)                  # the one-path kernel, which fills the diagnostics
    assert maps["other_surface"].shape == (6, 6)
    fog = load(ROOT / "scenes" / "fog-box.xml", res=6)
    assert not make("gpt-replay", fog, seed=0, effects="single-scattering").packets
    with pytest.raises(ValueError, match="packets"):
        make("gpt-replay", fog, seed=0, packets=True, effects="single-scattering")
