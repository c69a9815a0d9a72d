"""The XML loader against Mitsuba 3 itself: every shipped scene loads; defaults, transforms, camera,
emitters and media mean what Mitsuba makes of the same file (``mi.load_file`` + ``mi.traverse``).

Mitsuba computes in float32, so matrices and boxes agree to ~1e-6 relative; tolerances below are
1e-4 absolute on scene-sized quantities (|x| <= ~10): 100x float32 rounding, far below any real
disagreement (a wrong rotation sign or order moves corners by O(0.1..1)).
"""
from __future__ import annotations

import glob
import math
import os

import numpy as np
import pytest

from gdlearn.scene.load import load
from gdlearn.scene.model import SceneError

ROOT = os.path.join(os.path.dirname(__file__), "..")
SHIPPED = sorted(glob.glob(os.path.join(ROOT, "scenes", "*.xml")) +
                 glob.glob(os.path.join(ROOT, "scenes", "test", "*.xml")))
TOL = 1e-4

mi = pytest.importorskip("mitsuba")


@pytest.fixture(scope="module", autouse=True)
def _variant():
    mi.set_variant("scalar_rgb")


def _mi_load(path, **kw):
    return mi.load_file(path, optimize=False, **kw)   # no merging: one Mitsuba shape per <shape>


def _bbox(shape):
    """World bounding box of a gdlearn shape, computed here from its definition (not the loader)."""
    if shape.vertices is not None:
        return shape.vertices.min(0), shape.vertices.max(0)
    if shape.type == "sphere":
        c = shape.to_world[:3, 3]
        r = np.linalg.norm(shape.to_world[:3, 0])
        return c - r, c + r
    cube = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    if shape.type == "rectangle":
        pts = cube[cube[:, 2] == 1] * [1, 1, 0]
    elif shape.type == "disk":
        a = np.linspace(0, 2 * np.pi, 4096)
        pts = np.stack([np.cos(a), np.sin(a), 0 * a], 1)
    else:
        pts = cube
    w = pts @ shape.to_world[:3, :3].T + shape.to_world[:3, 3]
    return w.min(0), w.max(0)


def test_shipped_scenes_exist():
    names = {os.path.basename(p) for p in SHIPPED}
    assert {"cornell-box.xml", "fog-box.xml", "caustics-box.xml", "spot-medium.xml", "mesh.xml",
            "furnace-sphere.xml", "single-scatter.xml"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=os.path.basename)
def test_shipped_scene_matches_mitsuba(path):
    ours = load(path, res=16, spp=4)
    ref = _mi_load(path, res=16, spp=4)
    assert ours.sensor.film.width == ours.sensor.film.height == 16 and ours.sensor.spp == 4
    assert ours.sensor.film.rfilter == "box" and not ours.warnings
    # camera
    sp = mi.traverse(ref.sensors()[0])
    np.testing.assert_allclose(ours.sensor.to_world, np.array(sp["to_world"].matrix), atol=TOL)
    assert abs(_x_fov(ours.sensor) - sp["x_fov"]) < 1e-3
    # shapes, by id: same count, same world bounding box
    mshapes = {s.id(): s for s in ref.shapes()}
    assert len(mshapes) == len(ours.shapes)
    for s in ours.shapes:
        lo, hi = _bbox(s)
        bb = mshapes[s.id].bbox()
        tol = 2e-3 if s.type == "disk" else TOL    # the disk polygon above under-covers by ~1e-6
        np.testing.assert_allclose(lo, np.array(bb.min), atol=tol, err_msg=s.id)
        np.testing.assert_allclose(hi, np.array(bb.max), atol=tol, err_msg=s.id)
        assert (s.emitter is not None) == mshapes[s.id].is_emitter()
    # media: the camera's and every shape's interior, as Mitsuba traverses them
    _same_medium(ours.sensor.medium, ref.sensors()[0].get_medium())
    for s in ours.shapes:
        _same_medium(s.interior, mshapes[s.id].interior_medium())
        _same_medium(s.exterior, mshapes[s.id].exterior_medium())
    # point and spot lights: placement and angles
    lights = [e for e in ref.emitters() if str(e).startswith(("SpotLight", "PointLight"))]
    assert len(lights) == len([e for e in ours.emitters if e.type in ("spot", "point")])
    for e, m in zip([e for e in ours.emitters if e.type in ("spot", "point")], lights):
        mp = mi.traverse(m)
        if "position" in mp:
            np.testing.assert_allclose(e.position, np.array(mp["position"]).ravel(), atol=TOL)
        else:
            np.testing.assert_allclose(e.to_world, np.array(mp["to_world"].matrix), atol=TOL)
        if e.type == "spot":
            assert f"cutoff_angle = {e.cutoff_angle:g}" in str(m) and f"beam_width = {e.beam_width:g}" in str(m)
    # integrator
    integ = str(ref.integrator())
    assert integ.startswith("VolumetricSimplePathIntegrator" if ours.integrator.type == "volpath"
                            else "PathIntegrator")
    depth = ours.integrator.max_depth
    assert f"max_depth = {depth if depth >= 0 else 2**32 - 1}" in integ   # Mitsuba prints -1 as uint32


def _same_medium(ours, theirs):
    assert (ours is None) == (theirs is None)
    if ours is None:
        return
    p = mi.traverse(theirs)
    assert np.allclose(ours.sigma_t, p["scale"] * p["sigma_t.value.value"], rtol=1e-6)
    assert np.allclose(ours.albedo, p["albedo.value.value"], rtol=1e-6)
    assert abs(ours.g - (p["phase_function.g"] if "phase_function.g" in p else 0.0)) < 1e-6


def _x_fov(sensor):
    """Horizontal field of view from fov/fov_axis, as Mitsuba's perspective camera documents it."""
    w, h = sensor.film.width, sensor.film.height
    t = math.tan(math.radians(sensor.fov) / 2)
    axis = sensor.fov_axis
    if axis == "smaller":
        axis = "x" if w <= h else "y"
    if axis == "larger":
        axis = "x" if w >= h else "y"
    if axis == "x":
        return sensor.fov
    scale = {"y": w / h, "diagonal": w / math.hypot(w, h)}[axis]
    return math.degrees(2 * math.atan(t * scale))


def _write(tmp_path, body, name="s.xml"):
    p = tmp_path / name
    p.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    return str(p)


@pytest.mark.parametrize("axis", ["x", "y", "smaller", "larger", "diagonal"])
def test_fov_axis_matches_mitsuba(tmp_path, axis):
    p = _write(tmp_path, f"""<sensor type="perspective"><float name="fov" value="50"/>
        <string name="fov_axis" value="{axis}"/>
        <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="25"/>
        <rfilter type="box"/></film></sensor>""")
    ours = load(p)
    assert abs(_x_fov(ours.sensor) - mi.traverse(_mi_load(p).sensors()[0])["x_fov"]) < 1e-3


def test_default_fov_is_mitsubas_50mm_lens(tmp_path):
    p = _write(tmp_path, """<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="30"/>
        <integer name="height" value="20"/><rfilter type="box"/></film></sensor>""")
    ours = load(p)
    assert abs(_x_fov(ours.sensor) - mi.traverse(_mi_load(p).sensors()[0])["x_fov"]) < 1e-3


TRANSFORM_CASES = {
    "order": '<scale x="0.5" y="2" z="1"/><rotate y="1" angle="30"/><translate x="1" y="-2" z="0.5"/>',
    "matrix-then-rotate": '<matrix value="1 0 0 0.5  0 2 0 0  0 0 1 -1  0 0 0 1"/><rotate value="0.6, 0.8, 0" angle="-70"/>',
    "lookat-then-translate": '<lookat origin="1, 2, 3" target="0, 0.5, 0" up="0, 1, 0"/><translate value="0.25"/>',
    "lookat-no-up": '<lookat origin="0, 3, 0" target="0, 0, 0.2"/>',
    "scale-uniform-value": '<scale value="1.5"/><rotate z="1" angle="45"/>',
}


@pytest.mark.parametrize("name", sorted(TRANSFORM_CASES))
def test_transforms_equal_mitsubas(tmp_path, name):
    chain = TRANSFORM_CASES[name]
    body = "".join(f'<shape type="{t}" id="{t}"><transform name="to_world">{chain}</transform></shape>'
                   for t in ("rectangle", "cube", "disk"))
    if "lookat" in name:    # Mitsuba (and gdlearn) refuse scale factors in a camera transform
        body += f'<sensor type="perspective"><transform name="to_world">{chain}</transform></sensor>'
    p = _write(tmp_path, body)
    ours, ref = load(p), _mi_load(p)
    if "lookat" in name:
        np.testing.assert_allclose(ours.sensor.to_world,
                                   np.array(mi.traverse(ref.sensors()[0])["to_world"].matrix), atol=TOL)
    m = {s.id(): s.bbox() for s in ref.shapes()}
    for s in ours.shapes:
        lo, hi = _bbox(s)
        tol = 2e-3 if s.type == "disk" else TOL
        np.testing.assert_allclose(lo, np.array(m[s.id].min), atol=tol)
        np.testing.assert_allclose(hi, np.array(m[s.id].max), atol=tol)


def test_sphere_center_radius_folded_into_to_world(tmp_path):
    p = _write(tmp_path, """<shape type="sphere" id="s"><point name="center" x="1" y="2" z="3"/>
        <float name="radius" value="0.5"/><transform name="to_world"><translate x="-1"/></transform></shape>""")
    s = load(p).shapes[0]
    ref = mi.traverse(_mi_load(p).shapes()[0])
    np.testing.assert_allclose(s.to_world, np.array(ref["to_world"].matrix), atol=TOL)
    np.testing.assert_allclose(s.to_world[:3, 3], [0, 2, 3])      # by hand: T(-1,0,0) T(1,2,3) S(0.5)


def test_plugin_defaults_equal_mitsubas(tmp_path):
    p = _write(tmp_path, """
        <shape type="rectangle" id="d"/>
        <shape type="rectangle" id="rc"><bsdf type="roughconductor"/></shape>
        <shape type="rectangle" id="de"><bsdf type="dielectric"/></shape>
        <shape type="rectangle" id="rp"><bsdf type="roughplastic"/></shape>
        <medium type="homogeneous" id="m"><phase type="hg"/><float name="scale" value="3"/></medium>
        <shape type="cube" id="box"><bsdf type="null"/><ref name="interior" id="m"/></shape>
        <emitter type="spot" id="spot"><float name="cutoff_angle" value="30"/></emitter>""")
    sc, ref = load(p), _mi_load(p)
    by = {s.id: s for s in sc.shapes}
    assert by["d"].bsdf.type == "diffuse" and np.allclose(by["d"].bsdf.reflectance, 0.5)
    rc = by["rc"].bsdf
    assert (rc.alpha, rc.distribution) == (0.1, "beckmann") and np.allclose(rc.reflectance, 1.0)
    eta = {s.id(): s.bsdf() for s in ref.shapes()}
    assert abs(by["de"].bsdf.int_ior / by["de"].bsdf.ext_ior - mi.traverse(eta["de"])["eta"]) < 1e-5
    rp = by["rp"].bsdf
    assert abs(rp.int_ior / rp.ext_ior - mi.traverse(eta["rp"])["eta"]) < 1e-5
    assert abs(rp.alpha - mi.traverse(eta["rp"])["alpha"]) < 1e-7 and np.allclose(rp.reflectance, 0.5)
    med = by["box"].interior
    mp = mi.traverse(ref.shapes()[[s.id() for s in ref.shapes()].index("box")].interior_medium())
    assert np.allclose(med.sigma_t, 3.0) and np.allclose(med.albedo, mp["albedo.value.value"])
    assert abs(med.sigma_t[0] - mp["scale"] * mp["sigma_t.value.value"]) < 1e-6
    assert abs(med.g - mp["phase_function.g"]) < 1e-6 and med.g == pytest.approx(0.8)
    spot = sc.emitters[0]
    ms = str(ref.emitters()[0])
    assert spot.beam_width == pytest.approx(22.5) and "beam_width = 22.5" in ms


def test_defaults_and_overrides(tmp_path):
    p = _write(tmp_path, """<default name="w" value="20"/><default name="rho" value="0.3"/>
        <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="$w"/>
        <integer name="height" value="$w"/><rfilter type="box"/></film></sensor>
        <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="$rho, 0.1, $rho"/></bsdf></shape>""")
    sc = load(p)
    assert sc.sensor.film.width == 20 and np.allclose(sc.shapes[0].bsdf.reflectance, [0.3, 0.1, 0.3])
    sc = load(p, w=7, rho=0.9)
    assert sc.sensor.film.width == 7 and np.allclose(sc.shapes[0].bsdf.reflectance, [0.9, 0.1, 0.9])
    assert sc.effects is None


def test_effects_request_from_default(tmp_path):
    p = _write(tmp_path, '<default name="effects" value="direct, single-scattering"/><shape type="sphere"/>')
    assert load(p).effects == ["direct", "single-scattering"]
    assert load(p, effects="caustics").effects == ["caustics"]
    _mi_load(p)   # Mitsuba accepts (and ignores) the parameter


def test_shared_refs_are_one_object_and_media_sides(tmp_path):
    sc = load(os.path.join(ROOT, "scenes", "fog-box.xml"))
    fog = sc.sensor.medium
    assert fog is not None and all(s.interior is fog and s.exterior is fog for s in sc.shapes)
    assert len(sc.media) == 1
    spot = load(os.path.join(ROOT, "scenes", "spot-medium.xml"))
    block = [s for s in spot.shapes if s.id == "smoke-block"][0]
    assert block.bsdf.type == "null" and block.interior is not None and block.exterior is None
    assert spot.sensor.medium is None
    cb = load(os.path.join(ROOT, "scenes", "cornell-box.xml"))
    whites = [s.bsdf for s in cb.shapes if s.bsdf.id == "white"]
    assert len(whites) == 6 and all(b is whites[0] for b in whites)


def test_meshes_match_mitsuba_and_have_normals():
    path = os.path.join(ROOT, "scenes", "mesh.xml")
    sc = load(path)
    ref = {s.id(): s for s in _mi_load(path).shapes()}
    for s in sc.shapes:
        if s.type not in ("obj", "ply"):
            continue
        m = ref[s.id]
        assert s.face_normals and s.normals is None
        assert len(s.faces) == m.face_count()
        area = 0.5 * np.linalg.norm(np.cross(s.vertices[s.faces[:, 1]] - s.vertices[s.faces[:, 0]],
                                             s.vertices[s.faces[:, 2]] - s.vertices[s.faces[:, 0]]), axis=1).sum()
        assert abs(area - m.surface_area()) < 1e-4 * area


def test_smooth_normals_point_outwards(tmp_path):
    meshes = os.path.abspath(os.path.join(ROOT, "scenes", "meshes"))
    body = "".join(f'<shape type="{f.split(".")[1]}" id="{f}"><string name="filename" value="{meshes}/{f}"/>'
                   '<transform name="to_world"><scale x="2" y="1" z="0.5"/><translate x="3"/></transform></shape>'
                   for f in ("icosphere.obj", "blob.ply", "tetra.ply", "pedestal.obj"))
    sc = load(_write(tmp_path, body))
    for s in sc.shapes:
        assert s.normals is not None and np.allclose(np.linalg.norm(s.normals, axis=1), 1)
        c = s.vertices.mean(0)
        # a convex-ish closed mesh around its centroid: normals point away from it
        assert np.mean(np.einsum("ij,ij->i", s.normals, s.vertices - c) > 0) > 0.95, s.id


def test_polygon_obj_and_ascii_ply(tmp_path):
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\n")
    (tmp_path / "tri.ply").write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n"
                                      "property float y\nproperty float z\nelement face 2\n"
                                      "property list uchar int vertex_indices\nend_header\n"
                                      "0 0 0\n2 0 0\n2 2 0\n0 2 0\n3 0 1 2\n3 0 2 3\n")
    p = _write(tmp_path, '<shape type="obj" id="q"><string name="filename" value="quad.obj"/></shape>'
               '<shape type="ply" id="t"><string name="filename" value="tri.ply"/></shape>')
    q, t = load(p).shapes
    assert q.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and t.faces.shape == (2, 3)
    np.testing.assert_allclose(q.normals, [[0, 0, 1]] * 4)


def test_warnings_not_errors(tmp_path):
    p = _write(tmp_path, """<sensor type="perspective"><sampler type="stratified">
        <integer name="sample_count" value="9"/></sampler>
        <film type="hdrfilm"><rfilter type="gaussian"/></film></sensor><shape type="sphere"/>""")
    sc = load(p)
    assert sc.sensor.spp == 9 and sc.sensor.film.rfilter == "gaussian"
    assert any("gaussian" in w for w in sc.warnings) and any("stratified" in w for w in sc.warnings)


def test_error_is_a_value_error_with_fields(tmp_path):
    p = _write(tmp_path, '<shape type="teapot"/>')
    with pytest.raises(SceneError) as e:
        load(p)
    assert e.value.file == p and e.value.line == 2 and "fix:" in str(e.value)


def test_binary_ply_and_obj_negative_indices_refused(tmp_path):
    import struct
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty double x\n"
            "property double y\nproperty double z\nelement face 2\n"
            "property list uchar uint vertex_indices\nend_header\n").encode()
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]], dtype="<f8").tobytes()
    faces = struct.pack("<B3I", 3, 0, 1, 2) + struct.pack("<B3I", 3, 0, 4, 1)
    (tmp_path / "mixed.ply").write_bytes(head + verts + faces)
    p = _write(tmp_path, '<shape type="ply" id="a"><string name="filename" value="mixed.ply"/>'
               '<boolean name="face_normals" value="true"/></shape>')
    a, = load(p).shapes
    assert a.faces.tolist() == [[0, 1, 2], [0, 4, 1]] and a.normals is None
    ref = {s.id(): s for s in _mi_load(p).shapes()}
    assert ref["a"].face_count() == 2 and abs(ref["a"].surface_area() - 1.0) < 1e-6
    # Mitsuba refuses relative OBJ indices ("reference to invalid vertex"): so does gdlearn
    (tmp_path / "neg.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n")
    p = _write(tmp_path, '<shape type="obj" id="b"><string name="filename" value="neg.obj"/></shape>',
               name="neg.xml")
    with pytest.raises(SceneError, match="negative"):
        load(p)
    with pytest.raises(RuntimeError):
        _mi_load(p)


def test_directional_constant_and_twosided(tmp_path):
    p = _write(tmp_path, """<emitter type="directional"><vector name="direction" x="1" y="-1" z="0.5"/>
        <rgb name="irradiance" value="2, 3, 4"/></emitter>
        <emitter type="constant"><rgb name="radiance" value="0.25"/></emitter>
        <shape type="rectangle" id="r"><bsdf type="twosided"><bsdf type="plastic">
        <rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/></bsdf></bsdf></shape>""")
    sc, ref = load(p), _mi_load(p)
    d, c = sc.emitters
    mdir = [e for e in ref.emitters() if str(e).startswith("Directional")][0]
    z = np.array(mi.traverse(mdir)["to_world"].matrix)[:3, 2]
    np.testing.assert_allclose(d.direction, z / np.linalg.norm(z), atol=TOL)
    np.testing.assert_allclose(d.direction, np.array([1, -1, 0.5]) / 1.5, atol=1e-12)   # by hand
    assert np.allclose(d.irradiance, [2, 3, 4]) and c.type == "constant" and np.allclose(c.radiance, 0.25)
    b = sc.shapes[0].bsdf
    assert b.twosided and b.type == "plastic" and np.allclose(b.reflectance, [0.1, 0.2, 0.3])
    assert b.int_ior == 1.49 and "TwoSided" in str(ref.shapes()[0].bsdf())
