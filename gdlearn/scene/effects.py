"""The effects plan: which light transport a scene can show, which part was asked for, and therefore
which code paths run (ARCHITECTURE.md, "Effects, not switches").

``plan(scene, request=None) -> EffectsPlan``. The effect classes are those of
:mod:`gdlearn.kernels.pathclass` (emission, direct lighting, diffuse interreflection, glossy,
specular, caustics, single and multiple scattering, volume caustics; Heckbert's path notation).
What a scene *can* show follows from the vertex classes its materials and media produce:

* a BSDF gives surface vertices: ``diffuse`` D; conductors and dielectrics S; rough variants G when
  alpha >= the roughness threshold (``layout.ROUGHNESS_THRESHOLD``, 0.05), else S; ``plastic`` D or S;
  ``roughplastic`` D or G/S; ``null`` none (an index-matched interface is not a vertex);
* media give M vertices only with the ``volpath`` integrator (Mitsuba's ``path`` ignores media) and
  an albedo > 0 (a purely absorbing medium attenuates but never scatters);
* ``max_depth`` d (Mitsuba's meaning) allows at most d - 1 interior vertices: d = 1 emission only,
  d = 2 adds direct lighting and single scattering; emitters seen directly need an area or constant
  emitter (point, spot and directional lights are invisible to camera rays).

A request (CLI ``--effects``, Python ``request=``, or the scene file's
``<default name="effects" value="..."/>``: Mitsuba accepts and ignores it) is a comma list of class
names and groups: ``direct`` = emission + direct-lighting, ``volume`` = the three medium classes,
``surface`` = the six others, ``all``. The caller's request wins over the file's.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from gdlearn.kernels import layout
from gdlearn.kernels.pathclass import (ALL_MASK, CAUSTICS, CLASS_NAMES, DIFFUSE_INTERREFLECTION,
                                 DIRECT_LIGHTING, EMISSION, GLOSSY, MULTIPLE_SCATTERING, SINGLE_SCATTERING,
                                 SPECULAR, VOLUME_CAUSTICS, pc_max_interior)
from gdlearn.scene.model import Scene

_VOLUME = (SINGLE_SCATTERING, MULTIPLE_SCATTERING, VOLUME_CAUSTICS)
GROUPS = {
    "direct": (EMISSION, DIRECT_LIGHTING),
    "volume": _VOLUME,
    "surface": tuple(c for c in range(len(CLASS_NAMES)) if c not in _VOLUME),
    "all": tuple(range(len(CLASS_NAMES))),
}
# classes whose paths may contain a specular vertex that a shift must cross (manifold exploration)
_MAY_HOLD_SPECULAR = (DIRECT_LIGHTING, SPECULAR, CAUSTICS, VOLUME_CAUSTICS, MULTIPLE_SCATTERING)


class EffectsError(ValueError):
    """An effects request names something that is not an effect or group."""


def valid_names() -> list[str]:
    return list(CLASS_NAMES) + list(GROUPS)


def parse_request(request) -> int:
    """Class bit mask of a request: a comma separated string or a list of names (None: all)."""
    if request is None:
        return ALL_MASK
    items = request.split(",") if isinstance(request, str) else list(request)
    mask = 0
    for raw in items:
        name = str(raw).strip().lower().replace("_", "-").replace(" ", "-")
        if not name:
            continue
        if name in GROUPS:
            for c in GROUPS[name]:
                mask |= 1 << c
        elif name in CLASS_NAMES:
            mask |= 1 << CLASS_NAMES.index(name)
        else:
            raise EffectsError(f"unknown effect '{raw}'; valid names: {', '.join(valid_names())}")
    if mask == 0:
        raise EffectsError(f"empty effects request; valid names: {', '.join(valid_names())}")
    return mask


def names_of(mask: int) -> list[str]:
    return [n for c, n in enumerate(CLASS_NAMES) if (mask >> c) & 1]


@dataclass
class EffectsPlan:
    """What a scene can show, what was asked for, and what runs.

    ``possible[name]`` / ``why[name]``: can the scene show this effect, and why (not).
    ``requested``: the expanded request; ``source``: where it came from. ``mask``: class bits that
    will be rendered (requested and possible). Run flags for the kernels: ``media`` (volume code
    compiled in: the scene has media and the integrator is volpath), ``medium_scattering`` (scattering
    vertices in media are created), ``nee``, ``mis``, ``russian_roulette``, ``max_interior`` (-1:
    unbounded), ``specular_chains`` (paths cross specular vertices: manifold exploration for shifts),
    ``photons`` (caustic-type effects that photon or beam estimators render better).
    ``reasons[code path] = (runs, why)``.
    """
    scene_path: str
    integrator: str
    max_depth: int
    possible: dict = field(default_factory=dict)
    why: dict = field(default_factory=dict)
    requested: list = field(default_factory=list)
    source: str = "default (all)"
    mask: int = 0
    unavailable: list = field(default_factory=list)
    media: bool = False
    medium_scattering: bool = False
    nee: bool = False
    mis: bool = False
    russian_roulette: bool = False
    max_interior: int = -1
    specular_chains: bool = False
    photons: bool = False
    roughness_threshold: float = layout.ROUGHNESS_THRESHOLD
    vertex_classes: tuple = ()
    reasons: dict = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        """The effects that will be rendered."""
        return names_of(self.mask)

    @property
    def possible_mask(self) -> int:
        """The class bits of the effects the scene can show (``possible``)."""
        return sum(1 << c for c, name in enumerate(CLASS_NAMES) if self.possible.get(name))

    def describe(self) -> str:
        depth = "unbounded" if self.max_depth < 0 else str(self.max_depth)
        out = [f"Effects plan for {self.scene_path}  (integrator {self.integrator}, max_depth {depth})",
               f"  vertex classes the scene produces: {', '.join(self.vertex_classes) or 'none'}",
               f"  request: {'all' if len(self.requested) == len(CLASS_NAMES) else ', '.join(self.requested)}"
               f"  [{self.source}]", "",
               f"  {'effect':26s}{'possible':10s}{'rendered':10s}why"]
        for c, name in enumerate(CLASS_NAMES):
            yes = "yes" if self.possible[name] else "no"
            ren = "yes" if (self.mask >> c) & 1 else "-"
            out.append(f"  {name:26s}{yes:10s}{ren:10s}{self.why[name]}")
        if self.unavailable and self.source != "default (all)":
            out.append(f"\n  requested but impossible in this scene: {', '.join(self.unavailable)}")
        mi = "unbounded" if self.max_interior < 0 else str(self.max_interior)
        out += ["", f"  class mask {self.mask:#011b}, at most {mi} interior vertices per path", "",
                f"  {'code path':40s}{'runs':6s}why"]
        for key, (runs, why) in self.reasons.items():
            out.append(f"  {key:40s}{'yes' if runs else 'no':6s}{why}")
        return "\n".join(out)


def _bsdf_vertices(b, threshold) -> set:
    t = b.type
    rough_class = "G" if b.alpha >= threshold else "S"
    return {"diffuse": {"D"}, "conductor": {"S"}, "dielectric": {"S"}, "roughconductor": {rough_class},
            "roughdielectric": {rough_class}, "plastic": {"D", "S"}, "roughplastic": {"D", rough_class},
            "null": set()}[t]


def plan(scene: Scene, request=None, threshold: float = layout.ROUGHNESS_THRESHOLD) -> EffectsPlan:
    """Derive the effects plan of ``scene``; ``request`` (names, groups, comma string) overrides the
    scene file's own request. Raises :class:`EffectsError` for an unknown name."""
    integ = scene.integrator
    p = EffectsPlan(scene.path, integ.type, integ.max_depth, roughness_threshold=threshold)
    surf = set().union(*[_bsdf_vertices(s.bsdf, threshold) for s in scene.shapes]) if scene.shapes else set()
    media = scene.media
    vol = integ.type == "volpath" and bool(media)
    scatter = vol and any(float(m.albedo.max()) > 0 and float(m.sigma_t.max()) > 0 for m in media)
    vclasses = sorted(surf) + (["M"] if scatter else [])
    p.vertex_classes = tuple({"D": "diffuse", "G": "glossy", "S": "specular", "M": "medium"}[v] for v in vclasses)
    _possible(p, scene, surf, media, vol, scatter)
    _request(p, scene, request)
    _run_flags(p, scene, surf, media, vol, scatter)
    return p


def _possible(p, scene, surf, media, vol, scatter):
    d = scene.integrator.max_depth
    maxint = -1 if d < 0 else max(d - 1, 0)
    visible = [e.type for e in scene.emitters if e.type == "constant"] + (["area"] if scene.area_emitters else [])
    any_light = bool(scene.emitters or scene.area_emitters)
    m_why = ("no medium in the scene" if not media else
             f"integrator '{scene.integrator.type}' ignores media (as Mitsuba's path does; use volpath)"
             if not vol else "media only absorb (albedo 0)" if not scatter else "")
    S, nonS = "S" in surf, bool(surf & {"D", "G"})
    depth = (lambda k: maxint < 0 or maxint >= k)

    def rule(c, ok, yes, no, k):
        if not any_light:
            ok, no = False, "the scene has no emitter"
        elif d == 0:
            ok, no = False, "max_depth 0 renders nothing"
        elif ok and not depth(k):
            ok, no = False, f"needs {k} interior vertices, max_depth {d} allows {maxint}"
        p.possible[CLASS_NAMES[c]], p.why[CLASS_NAMES[c]] = ok, (yes if ok else no)

    rule(EMISSION, bool(visible), f"{' and '.join(visible)} emitter seen directly",
         "only point/spot/directional lights, which camera rays cannot hit", 0)
    rule(DIRECT_LIGHTING, bool(surf), "surfaces lit by the emitters", "no surface with a non-null BSDF", 1)
    rule(DIFFUSE_INTERREFLECTION, "D" in surf, "diffuse surfaces light each other", "no diffuse BSDF", 2)
    rule(GLOSSY, "G" in surf, f"rough BSDF with alpha >= {p.roughness_threshold}",
         f"no rough BSDF with alpha >= {p.roughness_threshold}", 2)
    rule(SPECULAR, S, "specular BSDF (smooth, or alpha below the threshold)",
         "no specular or near-specular BSDF", 2)
    rule(CAUSTICS, S and nonS, "specular surfaces focus light onto non-specular ones",
         "no specular BSDF" if not S else "no non-specular surface to receive a caustic", 2)
    rule(SINGLE_SCATTERING, scatter, "light scatters once in a medium", m_why, 1)
    rule(MULTIPLE_SCATTERING, scatter, "light scatters in a medium and elsewhere", m_why, 2)
    rule(VOLUME_CAUSTICS, scatter and S, "specular surfaces focus light into a medium",
         m_why or "no specular BSDF", 2)


def _request(p, scene, request):
    if request is not None:
        p.source = "caller"
    elif scene.effects is not None:
        request, p.source = scene.effects, f"scene file {scene.path}"
    try:
        want = parse_request(request)
    except EffectsError as err:
        if p.source.startswith("scene file"):
            raise EffectsError(f"{scene.path}: <default name=\"effects\">: {err}") from None
        raise
    p.requested = names_of(want)
    possible = p.possible_mask
    p.mask = want & possible
    p.unavailable = names_of(want & ~possible)


def _run_flags(p, scene, surf, media, vol, scatter):
    integ = scene.integrator
    bound = pc_max_interior.py_func(p.mask)          # plain Python: no JIT for a plan
    d = integ.max_depth
    depth_bound = -1 if d < 0 else max(d - 1, 0)
    p.max_interior = depth_bound if bound < 0 else (bound if depth_bound < 0 else min(bound, depth_bound))
    interior = p.mask & ~(1 << EMISSION)
    hittable = bool(scene.area_emitters) or any(e.type == "constant" for e in scene.emitters)
    delta = [e.type for e in scene.emitters if e.type in ("point", "spot", "directional")]
    vol_classes = any((p.mask >> c) & 1 for c in _VOLUME)

    p.media = vol
    p.reasons["volume code (compiled in)"] = (vol, (
        "the scene has media and the integrator is volpath" if vol else
        "no medium in the scene" if not media else
        f"integrator '{integ.type}' ignores media"))
    p.medium_scattering = vol_classes
    p.reasons["medium scattering vertices"] = (vol_classes, (
        f"rendering {', '.join(n for n in p.names if n in [CLASS_NAMES[c] for c in _VOLUME])}"
        if vol_classes else "no volume effect rendered" + (": media only attenuate (transmittance)"
                                                          if vol else "")))
    p.nee = bool(interior) and bool(scene.emitters or scene.area_emitters)
    p.reasons["next-event estimation"] = (p.nee, (
        f"rendering paths with interior vertices ({', '.join(names_of(interior))})" if p.nee else
        "only emission (or nothing) is rendered"))
    p.mis = p.nee and hittable
    p.reasons["MIS (emitter vs BSDF/phase sampling)"] = (p.mis, (
        "area/constant emitters can be reached by both strategies" if p.mis else
        "no next-event estimation" if not p.nee else
        f"only delta lights ({', '.join(delta)}): one strategy, nothing to weigh"))
    rr = p.max_interior < 0 or p.max_interior > integ.rr_depth
    p.russian_roulette = rr and bool(interior)
    p.reasons["Russian roulette"] = (p.russian_roulette, (
        f"paths may be longer than rr_depth {integ.rr_depth}" if p.russian_roulette else
        f"paths have at most {p.max_interior} interior vertices <= rr_depth {integ.rr_depth}"))
    spec_classes = [CLASS_NAMES[c] for c in _MAY_HOLD_SPECULAR if (p.mask >> c) & 1]
    p.specular_chains = "S" in surf and bool(spec_classes)
    p.reasons["specular chains (manifold exploration)"] = (p.specular_chains, (
        f"specular vertices on {', '.join(spec_classes)} paths" if p.specular_chains else
        "no specular BSDF" if "S" not in surf else "no rendered effect contains a specular vertex"))
    caus = [CLASS_NAMES[c] for c in (CAUSTICS, VOLUME_CAUSTICS) if (p.mask >> c) & 1]
    p.photons = bool(caus)
    p.reasons["photons (caustic estimators)"] = (p.photons, (
        f"{', '.join(caus)} rendered: photon/beam estimators capture them far better"
        + (f"; from {', '.join(delta)} lights only they can" if delta else "")
        if caus else "no caustic effect rendered"))


class _CallableModule(type(__import__("sys"))):
    """Importing this module sets ``gdlearn.scene.effects`` to the module itself, which would hide
    the package's lazy ``effects -> plan`` alias; calling the module calls :func:`plan`, so
    ``gdlearn.scene.effects(scene)`` works either way."""

    def __call__(self, scene, request=None, **kw):
        return plan(scene, request, **kw)


__import__("sys").modules[__name__].__class__ = _CallableModule
