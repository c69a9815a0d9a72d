"""The effects plan: what each shipped scene can show, request parsing, run flags, errors, CLI."""
from __future__ import annotations

import argparse
import os

import pytest

import gdlearn.scene
from gdlearn.commands import effects as effects_cmd
from gdlearn.scene.effects import EffectsError, parse_request, plan
from gdlearn.scene.load import load

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
SCATTER = {"single-scattering", "multiple-scattering", "volume-caustics"}


def scene(name, **kw):
    return load(os.path.join(ROOT, "scenes", name), **kw)


def possible(p):
    return {n for n, ok in p.possible.items() if ok}


def test_cornell_box_has_no_scattering_nor_caustics():
    p = plan(scene("cornell-box.xml"))
    assert possible(p) == {"emission", "direct-lighting", "diffuse-interreflection"}
    assert not p.media and not p.medium_scattering and not p.specular_chains and not p.photons
    assert p.nee and p.mis and p.russian_roulette and p.max_interior == 7    # max_depth 8
    assert p.names == ["emission", "direct-lighting", "diffuse-interreflection"]


def test_fog_box_has_scattering():
    p = plan(scene("fog-box.xml"))
    assert {"single-scattering", "multiple-scattering"} <= possible(p)
    assert "volume-caustics" not in possible(p)       # no specular surface to focus light
    assert p.media and p.medium_scattering


def test_caustics_box_has_caustics_and_specular_chains():
    p = plan(scene("caustics-box.xml"))
    assert {"caustics", "specular"} <= possible(p) and not possible(p) & SCATTER
    assert p.specular_chains and p.photons
    assert not plan(scene("caustics-box.xml"), "direct").photons


def test_spot_medium_cannot_show_emission_and_needs_no_mis():
    p = plan(scene("spot-medium.xml"))
    assert "emission" not in possible(p) and "single-scattering" in possible(p)
    assert p.nee and not p.mis                          # only a delta light: nothing to weigh


def test_path_integrator_on_a_medium_scene_has_no_media():
    sc = scene("fog-box.xml")
    sc.integrator.type = "path"
    p = plan(sc)
    assert not possible(p) & SCATTER and not p.media
    assert "ignores media" in p.why["single-scattering"]
    assert "ignores media" in p.reasons["volume code (compiled in)"][1]


@pytest.mark.parametrize("depth, want", [
    (1, {"emission"}),
    (2, {"emission", "direct-lighting", "single-scattering"}),
    (3, {"emission", "direct-lighting", "single-scattering", "diffuse-interreflection",
         "multiple-scattering"}),
])
def test_max_depth_limits_effects(depth, want):
    p = plan(scene("fog-box.xml", max_depth=depth))
    assert possible(p) == want and p.max_interior == depth - 1


def test_media_code_stays_for_attenuation_when_no_volume_effect_is_asked():
    p = plan(scene("fog-box.xml"), "direct")
    assert p.media and not p.medium_scattering          # transmittance still attenuates
    assert p.max_interior == 1 and not p.russian_roulette


def test_request_parsing():
    assert parse_request("direct") == 0b11
    assert parse_request(None) == parse_request("all") == 511
    assert parse_request("direct, single-scattering") == 0b1000011
    assert parse_request(["Caustics", "VOLUME_CAUSTICS"]) == (1 << 5) | (1 << 8)
    assert parse_request("volume") == (1 << 6) | (1 << 7) | (1 << 8)
    assert parse_request("surface") | parse_request("volume") == 511
    with pytest.raises(EffectsError) as e:
        parse_request("direct,sparkles")
    assert "sparkles" in str(e.value) and "diffuse-interreflection" in str(e.value) and "all" in str(e.value)
    with pytest.raises(EffectsError):
        parse_request(" , ")


def test_requested_but_impossible_is_reported_and_masked():
    p = plan(scene("cornell-box.xml"), "caustics,direct")
    assert p.names == ["emission", "direct-lighting"] and p.unavailable == ["caustics"]
    assert "caustics" in p.describe()


def test_scene_file_request_and_caller_override(tmp_path):
    f = tmp_path / "s.xml"
    f.write_text('<scene version="3.0.0"><default name="effects" value="single-scattering"/>'
                 '<integrator type="volpath"/><medium type="homogeneous" id="m"/>'
                 '<shape type="cube"><bsdf type="null"/><ref name="interior" id="m"/></shape>'
                 '<emitter type="point"><point name="position" x="0" y="0" z="0"/></emitter></scene>')
    sc = load(str(f))
    p = plan(sc)
    assert p.names == ["single-scattering"] and p.source.startswith("scene file")
    assert p.max_interior == 1 and not p.mis
    p = plan(sc, "multiple-scattering")
    assert p.names == ["multiple-scattering"] and p.source == "caller" and p.max_interior == -1
    sc.effects = ["fog-lights"]
    with pytest.raises(EffectsError) as e:
        plan(sc)
    assert str(f) in str(e.value) and "fog-lights" in str(e.value)


def test_roughness_threshold_decides_glossy_or_specular(tmp_path):
    def one(alpha):
        f = tmp_path / f"r{alpha}.xml"
        f.write_text('<scene version="3.0.0"><shape type="rectangle"><bsdf type="roughconductor">'
                     f'<float name="alpha" value="{alpha}"/></bsdf></shape><shape type="sphere">'
                     '<emitter type="area"/></shape></scene>')
        return possible(plan(load(str(f))))
    assert "glossy" in one(0.3) and "specular" not in one(0.3)
    assert "specular" in one(0.01) and "glossy" not in one(0.01)
    # the sphere light is diffuse 0.5 by default: a non-specular receiver, so caustics are possible
    assert "caustics" in one(0.01) and "caustics" not in one(0.3)


def test_no_emitter_shows_nothing(tmp_path):
    f = tmp_path / "dark.xml"
    f.write_text('<scene version="3.0.0"><shape type="sphere"/></scene>')
    p = plan(load(str(f)))
    assert not possible(p) and p.mask == 0 and "no emitter" in p.why["direct-lighting"]


def test_package_level_alias_and_describe():
    sc = scene("caustics-box.xml")
    p = gdlearn.scene.effects(sc, "caustics")
    assert p.names == ["caustics"]
    text = p.describe()
    for word in ("caustics", "next-event estimation", "Russian roulette", "specular chains", "why"):
        assert word in text


def _cli(argv):
    parser = argparse.ArgumentParser()
    effects_cmd.add_parser(parser.add_subparsers())
    args = parser.parse_args(["effects"] + argv)
    return args.func(args)


def test_cli_prints_the_plan(capsys):
    assert _cli([os.path.join(ROOT, "scenes", "fog-box.xml"), "--effects", "direct,single-scattering"]) == 0
    out = capsys.readouterr().out
    assert "single-scattering" in out and "volume code" in out and "[caller]" in out


def test_cli_unknown_effect_exits_2(capsys):
    assert _cli([os.path.join(ROOT, "scenes", "fog-box.xml"), "--effects", "sparkles"]) == 2
    assert "valid names" in capsys.readouterr().err
