"""The validated scene: plain dataclasses, the output of :mod:`gdlearn.scene.load`.

A ``Scene`` is what a scene file *means*, with Mitsuba 3's defaults already applied, every value
checked and every reference resolved. It knows nothing about numba; :mod:`gdlearn.scene.compile`
flattens it into arrays for the kernels, and :mod:`gdlearn.scene.effects` reads it to decide which
light transport the scene can show.

**Conventions**

* Colours are ``np.ndarray`` of shape ``(3,)``, float64, linear RGB.
* Transforms are 4x4 float64 matrices mapping object space to world space (Mitsuba's ``to_world``).
* Every element remembers where it came from (:class:`Source`) so later stages can still name the
  file and line of a bad value.
* Defaults are Mitsuba 3's documented plugin defaults (v3.9); each field's comment names it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class SceneError(ValueError):
    """A scene file cannot be used. The message names the file, the line and the fix.

    Raised by the loader for malformed XML, unknown plugins, dangling references and invalid
    values; the CLI prints ``str(err)`` and exits with status 2 instead of a traceback.
    """

    def __init__(self, file: str, line: int | None, message: str, fix: str):
        self.file, self.line, self.message, self.fix = file, line, message, fix
        where = f"{file}:{line}" if line is not None else file
        super().__init__(f"{where}: {message}\n  fix: {fix}")


@dataclass(frozen=True)
class Source:
    """Where an element was declared (for error messages in later stages)."""
    file: str = "<python>"
    line: int | None = None


def rgb(*v) -> np.ndarray:
    """An RGB triple as float64 array; ``rgb(0.5)`` is grey."""
    a = np.asarray(v[0] if len(v) == 1 else v, dtype=np.float64).reshape(-1)
    return np.full(3, a[0]) if a.size == 1 else a.copy()


def identity() -> np.ndarray:
    return np.eye(4)


@dataclass
class Integrator:
    """``<integrator type="path|volpath">``.

    max_depth: Mitsuba's meaning: 1 = emitters seen directly only, 2 = direct lighting, -1 = unbounded
    (terminated by Russian roulette). rr_depth: the depth at which Russian roulette starts (default 5).
    ``path`` ignores participating media entirely (as Mitsuba's ``path`` does); ``volpath`` handles them.
    """
    type: str = "path"
    max_depth: int = -1
    rr_depth: int = 5
    src: Source = field(default_factory=Source)


@dataclass
class Film:
    """``<film type="hdrfilm">``: width/height default 768x576; only the box filter is exact here."""
    width: int = 768
    height: int = 576
    rfilter: str = "gaussian"       # Mitsuba's default; gdlearn renders with a box and warns otherwise
    src: Source = field(default_factory=Source)


@dataclass
class Sensor:
    """``<sensor type="perspective">``. ``fov`` in degrees along ``fov_axis`` (x, y, smaller, larger,
    diagonal); ``near_clip`` 0.01, ``far_clip`` 10000; ``spp`` from ``<sampler sample_count>`` (default 4);
    ``medium``: the medium the camera sits in (``None``: vacuum)."""
    fov: float = 45.0
    fov_axis: str = "x"
    near_clip: float = 0.01
    far_clip: float = 10000.0
    to_world: np.ndarray = field(default_factory=identity)
    film: Film = field(default_factory=Film)
    spp: int = 4
    medium: "Medium | None" = None
    src: Source = field(default_factory=Source)


@dataclass
class Medium:
    """``<medium type="homogeneous">``: ``sigma_t`` (1/length, already multiplied by ``scale``),
    single-scattering ``albedo`` (default 0.75), phase ``isotropic`` (g = 0) or ``hg`` with ``g`` in (-1, 1)."""
    sigma_t: np.ndarray = field(default_factory=lambda: rgb(1.0))
    albedo: np.ndarray = field(default_factory=lambda: rgb(0.75))
    phase: str = "isotropic"
    g: float = 0.0
    id: str | None = None
    src: Source = field(default_factory=Source)


@dataclass
class BSDF:
    """One BSDF with Mitsuba 3's defaults.

    * ``type``: diffuse | conductor | roughconductor | dielectric | roughdielectric | plastic |
      roughplastic | null.
    * ``reflectance``: ``reflectance`` of diffuse (0.5), ``specular_reflectance`` of conductors
      (1.0, material ``none``), ``diffuse_reflectance`` of plastics (0.5).
    * ``specular_reflectance``: dielectrics' and plastics' specular reflectance scale (1.0).
    * ``specular_transmittance``: dielectrics' transmittance scale (1.0).
    * ``alpha``: microfacet roughness of the rough variants (0.1); ``distribution`` ggx | beckmann
      (Mitsuba's default: beckmann).
    * ``int_ior`` / ``ext_ior``: numeric indices (dielectric: 1.5046 / 1.000277; plastic: 1.49 / 1.000277).
    * ``nonlinear``: plastic's nonlinear internal scattering flag (false).
    * ``twosided``: wrapped in ``<bsdf type="twosided">``.
    """
    type: str = "diffuse"
    reflectance: np.ndarray = field(default_factory=lambda: rgb(0.5))
    specular_reflectance: np.ndarray = field(default_factory=lambda: rgb(1.0))
    specular_transmittance: np.ndarray = field(default_factory=lambda: rgb(1.0))
    alpha: float = 0.1
    distribution: str = "beckmann"
    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    nonlinear: bool = False
    twosided: bool = False
    id: str | None = None
    src: Source = field(default_factory=Source)


@dataclass
class Emitter:
    """Any emitter. ``type``: area | point | spot | directional | constant.

    area: ``radiance`` (attached to a shape). point: ``position`` (or ``to_world``), ``intensity``.
    spot: ``to_world`` (it shines along local +z), ``intensity``, ``cutoff_angle`` (20 degrees),
    ``beam_width`` (3/4 of cutoff_angle). directional: ``direction`` (world), ``irradiance``.
    constant: ``radiance``.
    """
    type: str
    radiance: np.ndarray = field(default_factory=lambda: rgb(1.0))
    intensity: np.ndarray = field(default_factory=lambda: rgb(1.0))
    irradiance: np.ndarray = field(default_factory=lambda: rgb(1.0))
    to_world: np.ndarray = field(default_factory=identity)
    position: np.ndarray | None = None
    direction: np.ndarray | None = None
    cutoff_angle: float = 20.0
    beam_width: float | None = None
    src: Source = field(default_factory=Source)


@dataclass
class Shape:
    """A shape. ``type``: rectangle | cube | sphere | disk | obj | ply.

    Analytic shapes live in object space and are placed by ``to_world`` (a sphere's ``center`` and
    ``radius`` are folded into ``to_world`` by the loader). Meshes carry world-space ``vertices``
    (V x 3 float64), ``faces`` (F x 3 int32) and optional per-vertex ``normals`` (V x 3) when
    ``face_normals`` is false. ``bsdf`` is never None after loading (Mitsuba's default: diffuse 0.5; black, diffuse 0, on a
    shape with an area emitter).
    ``interior`` / ``exterior`` are the media on the two sides (None = vacuum).
    """
    type: str
    to_world: np.ndarray = field(default_factory=identity)
    bsdf: BSDF = field(default_factory=BSDF)
    emitter: Emitter | None = None
    interior: Medium | None = None
    exterior: Medium | None = None
    flip_normals: bool = False
    face_normals: bool = False
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    filename: str | None = None
    id: str | None = None
    src: Source = field(default_factory=Source)


@dataclass
class Scene:
    """A whole scene: what :func:`gdlearn.scene.load` returns."""
    integrator: Integrator = field(default_factory=Integrator)
    sensor: Sensor = field(default_factory=Sensor)
    shapes: list[Shape] = field(default_factory=list)
    emitters: list[Emitter] = field(default_factory=list)   # non-area emitters
    path: str = "<python>"
    warnings: list[str] = field(default_factory=list)
    effects: list[str] | None = None   # effect names the scene file asks for (None: all it can show)

    @property
    def area_emitters(self) -> list[Shape]:
        return [s for s in self.shapes if s.emitter is not None]

    @property
    def media(self) -> list[Medium]:
        seen: dict[int, Medium] = {}
        for m in [self.sensor.medium] + [x for s in self.shapes for x in (s.interior, s.exterior)]:
            if m is not None:
                seen.setdefault(id(m), m)
        return list(seen.values())
