"""Randomized differential testing against Mitsuba 3: small random scenes from the documented subset.

Differential testing (McKeeman 1998) renders the same random input with two independent
implementations and flags any disagreement; here the inputs are scene files of the subset in
``scenes/README.md`` and the verdict is the noise-calibrated block test of
:mod:`gdlearn.crosscheck.compare` (both renderers' own standard errors, Bonferroni over the blocks, the
image mean within ``rel_bound``). A failing scene is shrunk greedily -- remove one element at a time
and keep the removal while the comparison still fails (delta debugging, Zeller & Hildebrandt 2002)
-- and the minimal XML is written with the command that reproduces it.

:func:`random_scene` draws, from one integer seed: a diffuse floor; 1-3 shapes (sphere, cube,
rectangle, disk) with random scale, rotation and position; every BSDF of the subset (diffuse,
conductor, roughconductor, dielectric, roughdielectric, plastic, roughplastic, twosided diffuse, and
null interfaces holding a medium); media none, global (the camera and every shape in one fog) or
bounded (a null cube or sphere with an interior medium, the camera inside or outside it); one or two
emitters of every type (area rectangle, point, spot, directional, constant); max_depth 1, 2, 3, 5 or
-1 (unbounded, Russian roulette). Shapes never share a plane with the floor (a tie between two
coplanar surfaces is broken differently by different renderers; not a bias).

``python -m gdlearn.crosscheck fuzz --count N`` runs N seeds (see :mod:`gdlearn.crosscheck.__main__`);
``--gradients gpt,gpt-replay`` checks the gradient integrators on the same scenes
(:func:`run_gradient_seed`: the mean gradient against the finite differences of the primal).
"""
from __future__ import annotations

import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gdlearn.crosscheck.compare import ImageStats, compare

RES = 16
BLOCK = 4
ALPHA = 1e-3
#: Image-mean bound for random scenes: looser than the shipped scenes' 3 % because a random scene's
#: image mean may rest on a few bright caustic paths; the block z-test still has full power.
REL_BOUND = 0.05
BATCHES = 8


@dataclass
class FuzzScene:
    """A random scene as a list of XML elements (so that it can be shrunk element by element)."""
    seed: int
    header: list = field(default_factory=list)       # integrator, sensor, media: never removed
    elements: list = field(default_factory=list)     # shapes and emitters: removable
    max_depth: int = 5

    def xml(self, keep=None) -> str:
        els = self.elements if keep is None else [e for i, e in enumerate(self.elements) if i in keep]
        body = "\n".join(self.header + els)
        return f'<?xml version="1.0" encoding="utf-8"?>\n<!-- gdlearn fuzz seed {self.seed} -->\n' \
               f'<scene version="3.0.0">\n{body}\n</scene>\n'


def _v(a):
    return ", ".join(f"{x:.4f}" for x in a)


def _bsdf(rng, allow_null=False):
    kinds = ["diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric", "plastic",
             "roughplastic", "twosided"]
    k = kinds[rng.integers(len(kinds))]
    c = _v(rng.uniform(0.2, 0.9, 3))
    a = f'<float name="alpha" value="{rng.uniform(0.1, 0.5):.3f}"/>'
    if k == "diffuse":
        return f'<bsdf type="diffuse"><rgb name="reflectance" value="{c}"/></bsdf>'
    if k == "twosided":
        return f'<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="{c}"/></bsdf></bsdf>'
    if k == "conductor":
        return f'<bsdf type="conductor"><string name="material" value="none"/><rgb name="specular_reflectance" value="{c}"/></bsdf>'
    if k == "roughconductor":
        return f'<bsdf type="roughconductor"><string name="material" value="none"/>{a}</bsdf>'
    if k == "dielectric":
        return f'<bsdf type="dielectric"><float name="int_ior" value="{rng.uniform(1.2, 1.7):.3f}"/></bsdf>'
    if k == "roughdielectric":
        return f'<bsdf type="roughdielectric"><float name="int_ior" value="{rng.uniform(1.2, 1.7):.3f}"/>{a}</bsdf>'
    if k == "plastic":
        return f'<bsdf type="plastic"><rgb name="diffuse_reflectance" value="{c}"/></bsdf>'
    return f'<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="{c}"/>{a}</bsdf>'


def _to_world(rng, scale, y_min):
    ang = rng.uniform(0, 360, 3)
    pos = (rng.uniform(-0.8, 0.8), rng.uniform(y_min, 0.6), rng.uniform(-0.8, 0.5))
    return (f'<transform name="to_world"><scale value="{scale:.4f}"/>'
            f'<rotate x="1" angle="{ang[0]:.3f}"/><rotate y="1" angle="{ang[1]:.3f}"/>'
            f'<rotate z="1" angle="{ang[2]:.3f}"/><translate value="{_v(pos)}"/></transform>')


def _emitter(rng, med_refs):
    k = ["area", "point", "spot", "directional", "constant"][rng.integers(5)]
    if k == "area":
        o = (rng.uniform(-1.5, 1.5), rng.uniform(1.0, 2.0), rng.uniform(-1.5, 1.5))
        return (f'<shape type="rectangle"><transform name="to_world"><scale value="{rng.uniform(0.2, 0.6):.3f}"/>'
                f'<lookat origin="{_v(o)}" target="0, -0.5, 0" up="0, 0, 1"/></transform>{med_refs}'
                f'<bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>'
                f'<emitter type="area"><rgb name="radiance" value="{_v(rng.uniform(3, 10, 3))}"/></emitter></shape>')
    if k == "point":
        return (f'<emitter type="point"><point name="position" value="{_v((rng.uniform(-1, 1), rng.uniform(0.8, 1.8), rng.uniform(-1, 1)))}"/>'
                f'<rgb name="intensity" value="{_v(rng.uniform(2, 6, 3))}"/></emitter>')
    if k == "spot":
        o = (rng.uniform(-1, 1), rng.uniform(1.2, 2.0), rng.uniform(-1, 1))
        return (f'<emitter type="spot"><transform name="to_world"><lookat origin="{_v(o)}" target="0, -1, 0" up="0, 0, 1"/></transform>'
                f'<rgb name="intensity" value="{_v(rng.uniform(5, 15, 3))}"/><float name="cutoff_angle" value="{rng.uniform(15, 40):.2f}"/></emitter>')
    if k == "directional":
        d = np.array([rng.uniform(-0.5, 0.5), -1.0, rng.uniform(-0.5, 0.5)])
        return f'<emitter type="directional"><vector name="direction" value="{_v(d / np.linalg.norm(d))}"/><rgb name="irradiance" value="{_v(rng.uniform(1, 3, 3))}"/></emitter>'
    return f'<emitter type="constant"><rgb name="radiance" value="{_v(rng.uniform(0.2, 0.8, 3))}"/></emitter>'


def random_scene(seed: int) -> FuzzScene:
    """The random scene of ``seed`` (see the module docstring for what it may contain)."""
    rng = np.random.default_rng([0x6D6C, seed])
    max_depth = int([1, 2, 3, 5, -1][rng.integers(5)])
    media = ["none", "global", "bounded"][rng.integers(3)]
    sc = FuzzScene(seed, max_depth=max_depth)
    integ = "path" if media == "none" else "volpath"
    sc.header.append(f'<integrator type="{integ}"><integer name="max_depth" value="{max_depth}"/></integrator>')
    med_xml = ""
    cam_in = False
    if media != "none":
        sig = rng.uniform(0.2, 2.0)
        g = rng.uniform(-0.6, 0.8) if rng.random() < 0.5 else 0.0
        phase = f'<phase type="hg"><float name="g" value="{g:.3f}"/></phase>' if g else '<phase type="isotropic"/>'
        med_xml = (f'<medium type="homogeneous" id="m"><float name="sigma_t" value="{sig:.3f}"/>'
                   f'<rgb name="albedo" value="{_v(rng.uniform(0.3, 0.95, 3))}"/>{phase}</medium>')
        sc.header.append(med_xml)
        cam_in = media == "global" or rng.random() < 0.5
    if media == "bounded" and cam_in:
        origin, target = (0.1, 0.0, 0.4), (0.0, -0.4, -1.0)
    else:
        origin, target = (rng.uniform(-0.8, 0.8), rng.uniform(0.4, 1.4), 3.2), (0.0, -0.3, 0.0)
    cam_med = '<ref id="m"/>' if cam_in else ""
    sc.header.append(
        f'<sensor type="perspective"><float name="fov" value="45"/><transform name="to_world">'
        f'<lookat origin="{_v(origin)}" target="{_v(target)}" up="0, 1, 0"/></transform>{cam_med}'
        f'<sampler type="independent"><integer name="sample_count" value="4"/></sampler>'
        f'<film type="hdrfilm"><integer name="width" value="{RES}"/><integer name="height" value="{RES}"/>'
        f'<rfilter type="box"/></film></sensor>')
    both = '<ref name="interior" id="m"/><ref name="exterior" id="m"/>' if media == "global" else ""
    sc.header.append(f'<shape type="rectangle" id="floor"><transform name="to_world"><scale value="3"/>'
                     f'<rotate x="1" angle="-90"/><translate y="-1"/></transform>{both}'
                     f'<bsdf type="diffuse"><rgb name="reflectance" value="{_v(rng.uniform(0.3, 0.8, 3))}"/></bsdf></shape>')
    if media == "bounded":
        kind = "cube" if rng.random() < 0.5 else "sphere"
        if cam_in:
            tw = '<transform name="to_world"><scale value="0.9"/><rotate y="1" angle="20"/></transform>'
        else:
            tw = _to_world(rng, rng.uniform(0.3, 0.6), -0.35)
        sc.header.append(f'<shape type="{kind}">{tw}<bsdf type="null"/><ref name="interior" id="m"/></shape>')
    for _ in range(int(rng.integers(1, 4))):
        kind = ["sphere", "cube", "rectangle", "disk"][rng.integers(4)]
        s = rng.uniform(0.15, 0.35)
        sc.elements.append(f'<shape type="{kind}">{_to_world(rng, s, -0.6)}{both}{_bsdf(rng)}</shape>')
    for _ in range(int(rng.integers(1, 3))):
        sc.elements.append(_emitter(rng, both))
    constants = [i for i, e in enumerate(sc.elements) if 'emitter type="constant"' in e]
    for i in reversed(constants[1:]):    # Mitsuba (and gdlearn) allow one environment emitter
        del sc.elements[i]
    if max_depth == 1 and not constants and not any('emitter type="area"' in e for e in sc.elements):
        # max_depth 1 renders only emitters seen directly: without an area light in the scene the
        # image would be 0 for both renderers (a vacuous pass). A constant background is seen
        # around the shapes, and through a bounded medium's transmittance. No random draw: the other
        # seeds keep their scenes.
        sc.elements.append('<emitter type="constant"><rgb name="radiance" value="0.5, 0.4, 0.3"/></emitter>')
    if media == "global" and any(_is_infinite(e) for e in sc.elements):
        _thin_global_medium(sc)
    return sc


#: Cap on the optical depth sigma_t * 2 r of a directional or constant emitter's shadow ray in a
#: global medium (r: the scene's bounding-sphere radius; the ray is at least 2 r long, more from a
#: vertex outside the sphere, ``lights.infinite_distance``). Mitsuba 3's volpath estimates that
#: transmittance by free-flight sampling: the ray survives with probability exp(-depth) and weighs
#: 1, else 0. At depth 10 (seed 0 before this cap: sigma_t 1.25, r 4.3) one sample in 2e4
#: survives, 8 renders of 128 spp hold a handful of fireflies and most blocks read exactly 0 with a
#: standard error of 0, so the block test flags noise it cannot see. Capped at ~2 (up to ~2.2: r is
#: only bounded below by the floor) every pixel keeps >= 10 % survivors on its shortest rays.
MAX_INFINITE_DEPTH = 2.0
_BSPHERE_R = 3.0 * np.sqrt(2.0)      # the floor alone (scale 3, corners at +-3): r >= this


def _is_infinite(element: str) -> bool:
    return 'emitter type="directional"' in element or 'emitter type="constant"' in element


def _thin_global_medium(sc: FuzzScene) -> None:
    """Cap sigma_t so the infinite emitters' shadow rays stay below MAX_INFINITE_DEPTH (using the
    floor's bounding radius, a lower bound of the scene's; no random draw, so other seeds keep their
    scenes)."""
    cap = MAX_INFINITE_DEPTH / (2.0 * _BSPHERE_R)
    for i, h in enumerate(sc.header):
        m = re.search(r'name="sigma_t" value="([0-9.]+)"', h)
        if m and float(m.group(1)) > cap:
            sc.header[i] = h.replace(m.group(0), f'name="sigma_t" value="{cap:.3f}"')


@dataclass
class Verdict:
    seed: int
    ok: bool
    summary: str
    xml: str
    max_depth: int
    inconclusive: bool = False


def _write(xml: str, folder) -> str:
    fd, path = tempfile.mkstemp(suffix=".xml", dir=folder)
    with os.fdopen(fd, "w") as f:
        f.write(xml)
    return path


def _stats_gdlearn(path, spp, inject=None):
    from gdlearn.integrators import make
    from gdlearn.scene.load import load
    scene = load(path)
    if inject is not None:
        inject(scene)
    integ = make("pt", scene, seed=1, spp_per_pass=spp, threads=2)
    integ.warmup()
    imgs, prev = [], None
    for _ in range(BATCHES):
        f = integ.step()
        imgs.append((f.primal * f.spp - (prev.primal * prev.spp if prev else 0.0)) / (f.spp - (prev.spp if prev else 0)))
        prev = f
    return ImageStats.from_samples(imgs)


def _stats_mitsuba(path, spp, variant):
    from gdlearn.crosscheck.mitsuba import render_mitsuba
    return ImageStats.from_samples([render_mitsuba(path, spp, 7000 + s, variant, 2) for s in range(BATCHES)])


def check_xml(xml: str, spp: int = 64, variant: str = "scalar_rgb", inject=None, folder=None):
    """Render ``xml`` with both renderers and compare: the :class:`~gdlearn.crosscheck.compare.Comparison`
    (Mitsuba gets twice gdlearn's samples, so the verdict's power comes mostly from gdlearn's noise)."""
    path = _write(xml, folder)
    try:
        test = _stats_gdlearn(path, spp, inject)
        ref = _stats_mitsuba(path, 2 * spp, variant)
    finally:
        os.unlink(path)
    return compare(test, ref, block=BLOCK, alpha=ALPHA, rel_bound=REL_BOUND)


#: A comparison that fails on an unresolved image mean alone (Comparison.inconclusive) is repeated
#: with 4x the samples, up to this many times; still unresolved, the seed counts as inconclusive
#: (neither a pass nor a bug). The block tests keep their full power at every step.
MAX_RETRIES = 2


def check_resolved(xml: str, spp: int = 64, variant: str = "scalar_rgb", inject=None):
    """:func:`check_xml` with more samples while the verdict is only inconclusive: ``(comparison, spp)``."""
    c = check_xml(xml, spp, variant, inject)
    for _ in range(MAX_RETRIES):
        if not c.inconclusive:
            break
        spp *= 4
        c = check_xml(xml, spp, variant, inject)
    return c, spp


def run_seed(seed: int, spp: int = 64, variant: str = "scalar_rgb", inject=None) -> Verdict:
    sc = random_scene(seed)
    c, used = check_resolved(sc.xml(), spp, variant, inject)
    note = f" [{used} spp per batch]" if used != spp else ""
    return Verdict(seed, c.ok, c.summary() + note, sc.xml(), sc.max_depth, c.inconclusive)


#: gradient mode: independent renders (seeds) and samples per pixel of each, per integrator
GRADIENT_SEEDS = 32
GRADIENT_SPP = 8


def run_gradient_seed(seed: int, integrator: str, n_seeds: int = GRADIENT_SEEDS, spp: int = GRADIENT_SPP,
                      broken: int = 0):
    """The random scene of ``seed`` through a gradient integrator (``gpt`` or ``gpt-replay``): are
    its gradients the finite differences of its own primal, in expectation?
    (:func:`gdlearn.crosscheck.gradients.render_check`; no Mitsuba needed: the primal is pt's estimator,
    which the image comparison checks against Mitsuba.) ``broken``: a planted bug of
    :mod:`gdlearn.integrators.path.gpt_surface.vertex` (``BROKEN_*``), to show the check can fail.
    Returns ``(GradientCheck, xml)``."""
    from gdlearn.crosscheck.gradients import render_check
    from gdlearn.scene.load import load
    xml = random_scene(seed).xml()
    path = _write(xml, None)
    try:
        scene = load(path)
    finally:
        os.unlink(path)
    return render_check(scene, integrator, n_seeds=n_seeds, spp=spp, threads=2, broken=broken), xml


def shrink(seed: int, spp: int = 64, variant: str = "scalar_rgb", inject=None) -> str:
    """Greedy one-element-at-a-time reduction of a failing scene (delta debugging's ddmin with
    granularity 1): drop a shape or an emitter while the comparison still fails; at least one
    emitter stays. Returns the minimal XML."""
    sc = random_scene(seed)
    keep = list(range(len(sc.elements)))
    changed = True
    while changed:
        changed = False
        for i in list(keep):
            trial = [k for k in keep if k != i]
            if not any("emitter" in sc.elements[k] for k in trial):
                continue
            c, _ = check_resolved(sc.xml(set(trial)), spp, variant, inject)
            if not (c.ok or c.inconclusive):
                keep, changed = trial, True
    return sc.xml(set(keep))


def write_failure(seed: int, xml: str, out_dir, inject_name: str | None = None) -> Path:
    """Write the minimal failing scene and a comment with the command that reproduces it."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    f = out / f"fuzz-{seed}.xml"
    cmd = f"python -m gdlearn.crosscheck fuzz --seed {seed} --count 1" + (f" --inject {inject_name}" if inject_name else "")
    f.write_text(re.sub(r"<!-- gdlearn fuzz seed \d+ -->",
                        f"<!-- gdlearn fuzz seed {seed}, minimal failing scene; reproduce: {cmd}; "
                        f"or compare this file: python -m gdlearn.crosscheck check {f.name} -->", xml))
    return f


#: Deliberate biases for showing that the fuzzer can fail (``--inject``): each edits the loaded
#: gdlearn scene only, so Mitsuba renders the true scene.
INJECTIONS = {
    "sigma_s*0.95": lambda scene: [setattr(m, "albedo", m.albedo * 0.95) for m in _media(scene)],
    "light*1.05": lambda scene: [setattr(e, k, getattr(e, k) * 1.05) for e in _emitters(scene)
                                 for k in ("radiance", "intensity", "irradiance")],
}


def _media(scene):
    seen = {}
    for s in scene.shapes:
        for m in (s.interior, s.exterior):
            if m is not None:
                seen[id(m)] = m
    if scene.sensor.medium is not None:
        seen[id(scene.sensor.medium)] = scene.sensor.medium
    return list(seen.values())


def _emitters(scene):
    return [s.emitter for s in scene.shapes if s.emitter is not None] + list(getattr(scene, "emitters", []))
