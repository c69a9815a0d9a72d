"""Builders for the non-shape plugins of the XML subset: bsdf, medium, emitter, sensor, film, sampler,
integrator. Each reads one element's :class:`~gdlearn.scene.xmlvalues.Props`, applies Mitsuba 3's
documented defaults (v3.9 plugin docs; the model's field comments name them), validates every value
and returns a :mod:`gdlearn.scene.model` dataclass. Shapes and references live in
:mod:`gdlearn.scene.load`, which passes itself in as ``ld`` (path, warnings, ``split``, ``resolve``).
"""
from __future__ import annotations

import math

import numpy as np

from gdlearn.scene.model import BSDF, Emitter, Film, Integrator, Medium, SceneError, Sensor, Source
from gdlearn.scene.transforms import coordinate_system, lookat, translate

#: Mitsuba 3's named indices of refraction (src/bsdfs/ior.h), for int_ior/ext_ior given as strings.
IOR_PRESETS = {"vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277,
               "carbon dioxide": 1.00045, "water": 1.333, "acetone": 1.36, "ethanol": 1.361,
               "carbon tetrachloride": 1.461, "glycerol": 1.4729, "benzene": 1.501,
               "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
               "pyrex": 1.47, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046,
               "sodium chloride": 1.544, "amber": 1.55, "pet": 1.575, "diamond": 2.419}

BSDF_PARAMS = {
    "diffuse": ("reflectance",),
    "conductor": ("material", "specular_reflectance"),
    "roughconductor": ("material", "specular_reflectance", "distribution", "alpha", "alpha_u",
                       "alpha_v", "sample_visible"),
    "dielectric": ("int_ior", "ext_ior", "specular_reflectance", "specular_transmittance"),
    "roughdielectric": ("int_ior", "ext_ior", "specular_reflectance", "specular_transmittance",
                        "distribution", "alpha", "alpha_u", "alpha_v", "sample_visible"),
    "plastic": ("diffuse_reflectance", "specular_reflectance", "int_ior", "ext_ior", "nonlinear"),
    "roughplastic": ("diffuse_reflectance", "specular_reflectance", "int_ior", "ext_ior", "nonlinear",
                     "distribution", "alpha", "sample_visible"),
    "null": (),
}
EMITTER_PARAMS = {"area": ("radiance",), "point": ("position", "intensity"),
                  "spot": ("intensity", "cutoff_angle", "beam_width"),
                  "directional": ("direction", "irradiance"), "constant": ("radiance",)}
FOV_AXES = ("x", "y", "smaller", "larger", "diagonal")
#: Mitsuba's perspective camera without ``fov``: a 50 mm lens on a 36 x 24 mm film, measured on the
#: film diagonal (sensor.h, parse_fov).
DEFAULT_FOV = math.degrees(2.0 * math.atan(math.hypot(36.0, 24.0) / (2.0 * 50.0)))


def _src(ld, node):
    return Source(ld.path, node.line)


def _type(ld, node, kind, allowed):
    t = node.attrs.get("type")
    if t not in allowed:
        got = f"type '{t}'" if t else "no type"
        raise SceneError(ld.path, node.line, f"<{kind}> with {got} is not in gdlearn's subset",
                         f"use one of: {', '.join(allowed)} (see scenes/README.md)")
    return t


def _nonneg(ld, props, name, value):
    if np.any(value < 0):
        raise SceneError(ld.path, props.line(name), f"{props.where} '{name}' is negative ({value.tolist()})",
                         f"give '{name}' values >= 0")
    return value


def _ior(ld, props, name, default):
    if not props.has(name):
        return default
    p = props.params[name]
    props.used.add(name)
    if p.tag == "string":
        key = p.value.strip().lower()
        if key not in IOR_PRESETS:
            raise SceneError(ld.path, p.node.line, f"unknown index of refraction '{p.value}'",
                             f"give a number or one of {', '.join(sorted(IOR_PRESETS))}")
        return IOR_PRESETS[key]
    v = props.float(name)
    if not v > 0:
        raise SceneError(ld.path, p.node.line, f"{props.where} '{name}' must be > 0, got {v}",
                         "give a positive index of refraction (glass 1.5, water 1.333, air 1.000277)")
    return v


def _roughness(ld, props, b: BSDF):
    dist = props.string("distribution", "beckmann")
    if dist not in ("beckmann", "ggx"):
        raise SceneError(ld.path, props.line("distribution"), f"unknown microfacet distribution '{dist}'",
                         'use "beckmann" (Mitsuba\'s default) or "ggx"')
    b.distribution = dist
    alpha = props.float("alpha", None)
    au, av = props.float("alpha_u", None), props.float("alpha_v", None)
    if au is not None or av is not None:
        if alpha is not None or au is None or av is None or au != av:
            raise SceneError(ld.path, props.line("alpha_u" if au is not None else "alpha_v"),
                             "anisotropic roughness (alpha_u != alpha_v) is not in gdlearn's subset",
                             "give one isotropic <float name=\"alpha\"/>")
        alpha = au
    b.alpha = 0.1 if alpha is None else alpha
    if not b.alpha > 0:
        name = "alpha" if props.has("alpha") else "alpha_u"
        raise SceneError(ld.path, props.line(name), f"{props.where} alpha must be > 0, got {b.alpha}",
                         "give alpha > 0 (use the smooth variant for a perfectly specular surface)")
    props.ignore("sample_visible", ld.warnings, "it changes only the noise, not the expected image")


def build_bsdf(ld, node) -> BSDF:
    """``<bsdf>``: Mitsuba 3 bsdf plugins diffuse, conductor, roughconductor, dielectric,
    roughdielectric, plastic, roughplastic, twosided and null."""
    t = _type(ld, node, "bsdf", tuple(BSDF_PARAMS) + ("twosided",))
    props, transforms, nested, refs = ld.split(node, f'<bsdf type="{t}">')
    ld.no_transforms(transforms, props.where)
    if t == "twosided":
        inner = [ld.build(n, "bsdf") for n in nested] + [ld.resolve(r, "bsdf") for r in refs]
        if len(inner) != 1 or inner[0].twosided:
            raise SceneError(ld.path, node.line, "<bsdf type=\"twosided\"> must wrap exactly one "
                             "one-sided BSDF", "put one <bsdf> (or <ref>) inside it")
        if inner[0].type in ("dielectric", "roughdielectric", "null"):
            # Mitsuba's twosided plugin refuses transmissive BSDFs (the back side is the inside)
            raise SceneError(ld.path, node.line, f'<bsdf type="twosided"> cannot wrap a '
                             f'transmissive "{inner[0].type}" BSDF (Mitsuba 3 refuses it too)',
                             f'remove the twosided wrapper: a "{inner[0].type}" BSDF is already seen '
                             'from both sides')
        props.finish(())
        b = BSDF(**{k: getattr(inner[0], k) for k in inner[0].__dataclass_fields__})
        b.twosided, b.id, b.src = True, node.attrs.get("id"), _src(ld, node)
        return b
    ld.no_children(nested + refs, props.where)
    b = BSDF(type=t, id=node.attrs.get("id"), src=_src(ld, node))
    if t == "diffuse":
        b.reflectance = _nonneg(ld, props, "reflectance", props.color("reflectance", 0.5))
    elif t in ("conductor", "roughconductor"):
        mat = props.string("material", "none")
        if mat != "none":
            raise SceneError(ld.path, props.line("material"),
                             f"conductor material '{mat}' is not in gdlearn's subset",
                             'use material "none" and set specular_reflectance to the colour')
        b.reflectance = _nonneg(ld, props, "specular_reflectance", props.color("specular_reflectance", 1.0))
    elif t in ("dielectric", "roughdielectric"):
        b.int_ior, b.ext_ior = _ior(ld, props, "int_ior", 1.5046), _ior(ld, props, "ext_ior", 1.000277)
        b.specular_reflectance = _nonneg(ld, props, "specular_reflectance",
                                         props.color("specular_reflectance", 1.0))
        b.specular_transmittance = _nonneg(ld, props, "specular_transmittance",
                                           props.color("specular_transmittance", 1.0))
    elif t in ("plastic", "roughplastic"):
        b.reflectance = _nonneg(ld, props, "diffuse_reflectance", props.color("diffuse_reflectance", 0.5))
        b.specular_reflectance = _nonneg(ld, props, "specular_reflectance",
                                         props.color("specular_reflectance", 1.0))
        b.int_ior, b.ext_ior = _ior(ld, props, "int_ior", 1.49), _ior(ld, props, "ext_ior", 1.000277)
        b.nonlinear = props.bool("nonlinear", False)
    if t.startswith("rough"):
        _roughness(ld, props, b)
    for name in ("reflectance", "diffuse_reflectance"):
        if props.has(name) and np.any(b.reflectance > 1):
            ld.warnings.append(f"{ld.path}:{props.line(name)}: {props.where} '{name}' > 1 creates energy")
    props.finish(BSDF_PARAMS[t])
    return b


def build_medium(ld, node) -> Medium:
    """``<medium type="homogeneous">`` with a ``<phase type="isotropic|hg">`` child (Mitsuba 3:
    sigma_t 1, albedo 0.75, scale 1 multiplying sigma_t; hg's g defaults to 0.8)."""
    _type(ld, node, "medium", ("homogeneous",))
    props, transforms, nested, refs = ld.split(node, '<medium type="homogeneous">')
    ld.no_transforms(transforms, props.where)
    ld.no_children(refs + [n for n in nested if n.tag != "phase"], props.where)
    m = Medium(id=node.attrs.get("id"), src=_src(ld, node))
    sigma_t = _nonneg(ld, props, "sigma_t", props.color("sigma_t", 1.0))
    scale = props.float("scale", 1.0)
    if not scale >= 0:
        raise SceneError(ld.path, props.line("scale"), f"medium scale must be >= 0, got {scale}",
                         "give a non-negative scale (it multiplies sigma_t)")
    m.sigma_t = sigma_t * scale
    m.albedo = props.color("albedo", 0.75)
    if np.any(m.albedo < 0) or np.any(m.albedo > 1):
        raise SceneError(ld.path, props.line("albedo"), f"medium albedo {m.albedo.tolist()} is outside [0, 1]",
                         "the single-scattering albedo sigma_s/sigma_t must lie in [0, 1]")
    props.ignore("sample_emitters", ld.warnings, "gdlearn always samples emitters from medium vertices")
    props.finish(("sigma_t", "albedo", "scale", "sample_emitters"))
    phases = [n for n in nested if n.tag == "phase"]
    if len(phases) > 1:
        raise SceneError(ld.path, phases[1].line, "a medium has more than one <phase>",
                         "a medium has one phase function: remove the others")
    if phases:
        ph = phases[0]
        m.phase = _type(ld, ph, "phase", ("isotropic", "hg"))
        pp, pt, pn, pr = ld.split(ph, f'<phase type="{m.phase}">')
        ld.no_transforms(pt, pp.where)
        ld.no_children(pn + pr, pp.where)
        if m.phase == "hg":
            m.g = pp.float("g", 0.8)
            if not -1 < m.g < 1:
                raise SceneError(ld.path, pp.line("g"), f"Henyey-Greenstein g = {m.g} is outside (-1, 1)",
                                 "give -1 < g < 1 (0 is isotropic; 0.999 is already extremely peaked)")
        pp.finish(("g",) if m.phase == "hg" else ())
    return m


def build_emitter(ld, node, in_shape: bool) -> Emitter:
    """``<emitter>``: area (inside a shape), point, spot, directional, constant (Mitsuba 3 defaults:
    radiance/intensity/irradiance 1; spot cutoff_angle 20 deg, beam_width 3/4 of the cutoff)."""
    t = _type(ld, node, "emitter", tuple(EMITTER_PARAMS))
    if (t == "area") != in_shape:
        fix = ("put the area emitter inside a <shape>" if t == "area"
               else "move this emitter to the top level of the scene")
        raise SceneError(ld.path, node.line, f"an emitter of type '{t}' cannot be "
                         f"{'outside' if t == 'area' else 'inside'} a shape", fix)
    props, transforms, nested, refs = ld.split(node, f'<emitter type="{t}">')
    ld.no_children(nested + refs, props.where)
    e = Emitter(type=t, src=_src(ld, node))
    to_world = ld.take_to_world(transforms, props.where, allowed=t in ("point", "spot", "directional"))
    if t in ("area", "constant"):
        e.radiance = _nonneg(ld, props, "radiance", props.color("radiance", 1.0))
    elif t in ("point", "spot"):
        e.intensity = _nonneg(ld, props, "intensity", props.color("intensity", 1.0))
        pos = props.vector("position", None) if t == "point" else None
        if pos is not None:
            if to_world is not None:
                raise SceneError(ld.path, props.line("position"),
                                 "give either 'position' or a to_world transform, not both",
                                 "keep one of them (position is a translation)")
            to_world = translate(pos)
        e.to_world = np.eye(4) if to_world is None else to_world
        e.position = e.to_world[:3, 3].copy()
    elif t == "directional":
        e.irradiance = _nonneg(ld, props, "irradiance", props.color("irradiance", 1.0))
        d = props.vector("direction", None)
        if d is not None:
            if to_world is not None or not np.any(d):
                raise SceneError(ld.path, props.line("direction"), "invalid directional 'direction' "
                                 "(zero, or given together with to_world)", "give one non-zero direction")
            up, _ = coordinate_system(d / np.linalg.norm(d))
            to_world = lookat(np.zeros(3), d, up)
        e.to_world = np.eye(4) if to_world is None else to_world
        z = e.to_world[:3, 2]
        e.direction = z / np.linalg.norm(z)
    if t == "spot":
        e.cutoff_angle = props.float("cutoff_angle", 20.0)
        e.beam_width = props.float("beam_width", 0.75 * e.cutoff_angle)
        if not (0 < e.cutoff_angle < 180 and 0 < e.beam_width <= e.cutoff_angle):
            raise SceneError(ld.path, props.line("cutoff_angle" if props.has("cutoff_angle") else "beam_width"),
                             f"spot angles invalid: cutoff_angle {e.cutoff_angle}, beam_width {e.beam_width}",
                             "give 0 < beam_width <= cutoff_angle < 180 (degrees)")
    props.finish(EMITTER_PARAMS[t])
    return e


def build_integrator(ld, node) -> Integrator:
    """``<integrator type="path|volpath">``: max_depth (-1 = unbounded), rr_depth (5)."""
    t = _type(ld, node, "integrator", ("path", "volpath"))
    props, transforms, nested, refs = ld.split(node, f'<integrator type="{t}">')
    ld.no_transforms(transforms, props.where)
    ld.no_children(nested + refs, props.where)
    it = Integrator(type=t, max_depth=props.int("max_depth", -1), rr_depth=props.int("rr_depth", 5),
                    src=_src(ld, node))
    if it.max_depth < -1:
        raise SceneError(ld.path, props.line("max_depth"), f"max_depth = {it.max_depth} is invalid",
                         "give -1 (unbounded) or a depth >= 0 (1 = emitters only, 2 = direct light)")
    if it.rr_depth <= 0:
        raise SceneError(ld.path, props.line("rr_depth"), f"rr_depth = {it.rr_depth} must be > 0",
                         "give rr_depth >= 1 (Mitsuba's default is 5)")
    if props.has("hide_emitters") and props.bool("hide_emitters"):
        raise SceneError(ld.path, props.line("hide_emitters"), "hide_emitters is not in gdlearn's subset",
                         "remove it (emitters are always visible)")
    props.finish(("max_depth", "rr_depth", "hide_emitters"))
    return it


def build_sensor(ld, node) -> Sensor:
    """``<sensor type="perspective">`` with film, sampler and an optional medium (the camera's)."""
    _type(ld, node, "sensor", ("perspective",))
    props, transforms, nested, refs = ld.split(node, '<sensor type="perspective">')
    s = Sensor(src=_src(ld, node))
    tw = ld.take_to_world(transforms, props.where, allowed=True)
    s.to_world = np.eye(4) if tw is None else tw
    if np.any(np.abs(np.linalg.norm(s.to_world[:3, :3], axis=0) - 1) > 1e-3):
        line = transforms["to_world"][1].line
        raise SceneError(ld.path, line, "the camera's to_world contains a scale factor (Mitsuba refuses it)",
                         "place the camera with <lookat>, <rotate> and <translate> only")
    s.fov = props.float("fov", None)
    s.fov_axis = props.string("fov_axis", "x" if s.fov is not None else "diagonal")
    if s.fov is None:
        s.fov = DEFAULT_FOV
    if not 0 < s.fov < 180:
        raise SceneError(ld.path, props.line("fov"), f"fov = {s.fov} is outside (0, 180) degrees",
                         "give the field of view in degrees, e.g. 40")
    if s.fov_axis not in FOV_AXES:
        raise SceneError(ld.path, props.line("fov_axis"), f"unknown fov_axis '{s.fov_axis}'",
                         f"use one of {', '.join(FOV_AXES)}")
    s.near_clip, s.far_clip = props.float("near_clip", 0.01), props.float("far_clip", 10000.0)
    if not 0 < s.near_clip < s.far_clip:
        raise SceneError(ld.path, props.line("near_clip"), "need 0 < near_clip < far_clip",
                         "give near_clip > 0 (default 0.01) and far_clip larger (default 10000)")
    props.finish(("fov", "fov_axis", "near_clip", "far_clip"))
    film_seen = False
    for n in nested:
        if n.tag == "film":
            s.film, film_seen = build_film(ld, n), True
        elif n.tag == "sampler":
            s.spp = build_sampler(ld, n)
        elif n.tag == "medium":
            s.medium = ld.build(n, "medium")
        else:
            ld.no_children([n], props.where)
    for r in refs:
        s.medium = ld.resolve(r, "medium")
    if not film_seen:
        ld.warnings.append(f"{ld.path}:{node.line}: no <film>: Mitsuba's default 768x576 hdrfilm "
                           "with a gaussian filter; gdlearn renders a box filter")
    return s


def build_film(ld, node) -> Film:
    _type(ld, node, "film", ("hdrfilm",))
    props, transforms, nested, refs = ld.split(node, '<film type="hdrfilm">')
    ld.no_transforms(transforms, props.where)
    f = Film(width=props.int("width", 768), height=props.int("height", 576), src=_src(ld, node))
    if f.width <= 0 or f.height <= 0:
        raise SceneError(ld.path, props.line("width" if f.width <= 0 else "height"),
                         f"film size {f.width}x{f.height} is invalid", "give width and height >= 1")
    for name in ("pixel_format", "component_format", "file_format"):
        props.ignore(name, ld.warnings, "gdlearn writes float RGB")
    props.finish(("width", "height", "pixel_format", "component_format", "file_format"))
    filters = [n for n in nested if n.tag == "rfilter"]
    ld.no_children(refs + [n for n in nested if n.tag != "rfilter"], props.where)
    if filters:
        f.rfilter = _type(ld, filters[0], "rfilter",
                          ("box", "tent", "gaussian", "mitchell", "catmullrom", "lanczos"))
    if f.rfilter != "box":
        ld.warnings.append(f"{ld.path}:{(filters[0] if filters else node).line}: reconstruction filter "
                           f"'{f.rfilter}' is rendered as a box filter by gdlearn (Mitsuba's image will "
                           "differ slightly); use <rfilter type=\"box\"/> to match")
    return f


def build_sampler(ld, node) -> int:
    t = _type(ld, node, "sampler", ("independent", "stratified", "multijitter", "orthogonal", "ldsampler"))
    props, transforms, nested, refs = ld.split(node, f'<sampler type="{t}">')
    ld.no_transforms(transforms, props.where)
    ld.no_children(nested + refs, props.where)
    spp = props.int("sample_count", 4)
    if spp <= 0:
        raise SceneError(ld.path, props.line("sample_count"), f"sample_count = {spp} must be >= 1",
                         "give a positive number of samples per pixel")
    props.ignore("seed", ld.warnings, "gdlearn takes the seed from render(..., seed=)")
    props.ignore("jitter", ld.warnings, "gdlearn's counter-based sampler does not stratify")
    props.finish(("sample_count", "seed", "jitter"))
    if t != "independent":
        ld.warnings.append(f"{ld.path}:{node.line}: sampler '{t}' is replaced by gdlearn's independent "
                           "counter-based sampler (same expectation, different noise)")
    return spp
