"""``load(path, **defaults) -> Scene``: the documented subset of Mitsuba 3's XML (scenes/README.md).

The road (ARCHITECTURE.md): XML text -> elements with line numbers and ``$name`` substituted
(:mod:`!.xmlvalues`) -> one builder per plugin (:mod:`!.plugins`; shapes and references here) ->
a validated :class:`~gdlearn.scene.model.Scene`. Semantics and defaults are Mitsuba 3's (v3.9):
a scene that loads here loads in ``mitsuba.load_file`` with the same keyword arguments and means
the same thing. Anything outside the subset, and any invalid value, raises one
:class:`~gdlearn.scene.model.SceneError` naming the file, the line and the fix.

Shapes (Mitsuba 3 shape plugins): ``rectangle`` = [-1,1]^2 at z=0 with normal +z; ``cube`` =
[-1,1]^3; ``disk`` = unit disk at z=0, normal +z; ``sphere`` = ``center`` (0,0,0) and ``radius`` (1)
folded into ``to_world`` as ``to_world @ T(center) @ S(radius)``; ``obj``/``ply`` meshes are read by
:mod:`!.meshio` and stored in world space (vertex normals unless ``face_normals``). A shape without a
bsdf gets Mitsuba's default: diffuse 0.5, or diffuse 0 (black) when the shape carries an area
emitter (Mitsuba 3's ``Shape`` constructor sets ``reflectance`` to 0 for emitters).
"""
from __future__ import annotations

import os

import numpy as np

from gdlearn.scene import plugins
from gdlearn.scene.meshio import MeshError, read_obj, read_ply, transform_mesh, triangle_areas, vertex_normals
from gdlearn.scene.model import BSDF, Scene, SceneError, Shape, Source, rgb
from gdlearn.scene.transforms import parse_transform, scale, translate
from gdlearn.scene.xmlvalues import VALUE_TAGS, Node, Props, collect_defaults, parse_xml, substitute

PLUGIN_TAGS = ("integrator", "sensor", "film", "sampler", "rfilter", "shape", "bsdf", "emitter",
               "medium", "phase")
SHAPE_TYPES = ("rectangle", "cube", "sphere", "disk", "obj", "ply")
SHAPE_PARAMS = {"rectangle": ("flip_normals",), "cube": ("flip_normals",), "disk": ("flip_normals",),
                "sphere": ("center", "radius", "flip_normals"),
                "obj": ("filename", "face_normals", "flip_normals", "flip_tex_coords"),
                "ply": ("filename", "face_normals", "flip_normals", "flip_tex_coords")}
_BUILDERS = {"bsdf": plugins.build_bsdf, "medium": plugins.build_medium}


def load(path: str, **defaults) -> Scene:
    """Load a scene file. Keyword arguments override its ``<default>`` parameters, exactly like
    ``mitsuba.load_file(path, **defaults)``: ``load("scenes/cornell-box.xml", res=64, spp=16)``."""
    return _Loader(os.fspath(path)).run(defaults)


class _Loader:
    def __init__(self, path: str):
        self.path = path
        self.warnings: list[str] = []
        self.decl: dict[str, Node] = {}        # id -> element
        self.built: dict[int, object] = {}     # id(element) -> built object (shared by refs)
        self.building: set[int] = set()

    # ----------------------------------------------------------------- driver
    def run(self, defaults: dict) -> Scene:
        root = parse_xml(self.path)
        if root.tag != "scene":
            raise SceneError(self.path, root.line, f"the root element is <{root.tag}>, not <scene>",
                             'wrap the scene in <scene version="3.0.0"> ... </scene>')
        if "version" not in root.attrs:
            raise SceneError(self.path, root.line, "<scene> has no version attribute (Mitsuba needs it)",
                             'write <scene version="3.0.0">')
        params = collect_defaults(self.path, root, defaults)
        substitute(self.path, root, params)
        self._declare(root)
        scene = Scene(path=self.path, warnings=self.warnings)
        seen_sensor = seen_integrator = False
        for node in root.children:
            tag = node.tag
            if tag == "default":
                continue
            if tag == "integrator":
                self._once(node, seen_integrator)
                scene.integrator, seen_integrator = plugins.build_integrator(self, node), True
            elif tag == "sensor":
                self._once(node, seen_sensor)
                scene.sensor, seen_sensor = plugins.build_sensor(self, node), True
            elif tag == "shape":
                scene.shapes.append(self.build_shape(node))
            elif tag == "emitter":
                scene.emitters.append(plugins.build_emitter(self, node, in_shape=False))
            elif tag in ("bsdf", "medium"):
                self.build(node, tag)
            else:
                raise SceneError(self.path, node.line, f"<{tag}> is not in gdlearn's subset of Mitsuba XML",
                                 "use only default, integrator, sensor, shape, emitter, bsdf, medium at "
                                 "the top level (see scenes/README.md)")
        if not seen_sensor:
            scene.sensor.fov, scene.sensor.fov_axis = plugins.DEFAULT_FOV, "diagonal"
            self.warnings.append(f"{self.path}: no <sensor>: Mitsuba's scene would have no camera; gdlearn "
                                 "uses a default perspective camera at the origin looking along +z")
        if not seen_integrator:
            self.warnings.append(f"{self.path}: no <integrator>: gdlearn uses path with max_depth -1 "
                                 "(give one so that Mitsuba renders the same)")
        if "effects" in params:
            scene.effects = [e.strip() for e in params["effects"].split(",") if e.strip()]
        if not scene.shapes and not scene.emitters:
            self.warnings.append(f"{self.path}: the scene has no shapes and no emitters: it renders black")
        return scene

    def _once(self, node, seen):
        if seen:
            raise SceneError(self.path, node.line, f"a second <{node.tag}>",
                             f"a scene has at most one <{node.tag}>: remove the other")

    def _declare(self, node: Node):
        for child in node.children:
            if "id" in child.attrs and child.tag in PLUGIN_TAGS:
                key = child.attrs["id"]
                if key in self.decl:
                    raise SceneError(self.path, child.line, f"id '{key}' is declared twice "
                                     f"(first on line {self.decl[key].line})", "give each id a unique name")
                self.decl[key] = child
            self._declare(child)

    # -------------------------------------------------------- shared helpers
    def split(self, node: Node, where: str):
        """Parameters, named transforms, nested plugin elements and refs of one plugin element."""
        props = Props(self.path, node, where)
        transforms, nested, refs = {}, [], []
        allowed_attrs = {"type", "id", "name"}
        extra = sorted(set(node.attrs) - allowed_attrs)
        if extra:
            raise SceneError(self.path, node.line, f"{where} has unknown attribute(s) {', '.join(extra)}",
                             "plugin elements take only type, id and name")
        for c in node.children:
            if c.tag in VALUE_TAGS:
                props.add(c)
            elif c.tag == "transform":
                name = c.attrs.get("name", "")
                if name in transforms:
                    raise SceneError(self.path, c.line, f"transform '{name}' of {where} is set twice",
                                     "merge the two transforms")
                transforms[name] = (parse_transform(self.path, c), c)
            elif c.tag == "ref":
                bad = sorted(set(c.attrs) - {"id", "name"})
                if "id" not in c.attrs or bad:
                    raise SceneError(self.path, c.line, "<ref> needs an id (and optionally a name)",
                                     'write <ref id="white"/> or <ref name="interior" id="fog"/>')
                refs.append(c)
            elif c.tag in PLUGIN_TAGS:
                nested.append(c)
            else:
                raise SceneError(self.path, c.line, f"<{c.tag}> inside {where} is not in gdlearn's subset",
                                 "use value tags (float, integer, boolean, string, rgb, point, vector), "
                                 "transform, ref or nested plugins (see scenes/README.md)")
        return props, transforms, nested, refs

    def no_transforms(self, transforms: dict, where: str):
        for name, (_, node) in transforms.items():
            raise SceneError(self.path, node.line, f"{where} takes no transform ('{name}')",
                             "remove the <transform>")

    def no_children(self, nodes: list, where: str):
        for n in nodes:
            raise SceneError(self.path, n.line, f"<{n.tag}> is not allowed inside {where}",
                             "move it where it belongs or remove it (see scenes/README.md)")

    def take_to_world(self, transforms: dict, where: str, allowed: bool):
        for name, (m, node) in transforms.items():
            if name != "to_world" or not allowed:
                raise SceneError(self.path, node.line, f"{where} has no transform '{name}'",
                                 'use <transform name="to_world">' if allowed else "remove the <transform>")
            return m
        return None

    def build(self, node: Node, kind: str):
        """Build a bsdf or medium element once; refs to its id share the same object."""
        if node.tag != kind:
            raise SceneError(self.path, node.line, f"expected a <{kind}> here, found <{node.tag}>",
                             f"put a <{kind}> here")
        key = id(node)
        if key in self.built:
            return self.built[key]
        if key in self.building:
            raise SceneError(self.path, node.line, f"<{kind}> refers to itself", "break the reference cycle")
        self.building.add(key)
        obj = _BUILDERS[kind](self, node)
        self.building.discard(key)
        self.built[key] = obj
        return obj

    def resolve(self, ref: Node, kind: str):
        target = self.decl.get(ref.attrs["id"])
        if target is None:
            known = ", ".join(sorted(k for k, n in self.decl.items() if n.tag == kind)) or "none"
            raise SceneError(self.path, ref.line, f"<ref id=\"{ref.attrs['id']}\"> refers to nothing",
                             f"declare an element with that id, or use one of the {kind} ids: {known}")
        if target.tag != kind:
            raise SceneError(self.path, ref.line, f"<ref id=\"{ref.attrs['id']}\"> is a <{target.tag}> "
                             f"(line {target.line}), but a <{kind}> is needed here",
                             f"refer to a <{kind}>")
        return self.build(target, kind)

    # ----------------------------------------------------------------- shapes
    def build_shape(self, node: Node) -> Shape:
        t = plugins._type(self, node, "shape", SHAPE_TYPES)
        where = f'<shape type="{t}">'
        props, transforms, nested, refs = self.split(node, where)
        s = Shape(type=t, id=node.attrs.get("id"), src=Source(self.path, node.line))
        tw = self.take_to_world(transforms, where, allowed=True)
        s.to_world = np.eye(4) if tw is None else tw
        s.flip_normals = props.bool("flip_normals", False)
        self._shape_children(s, nested, refs, where)
        if t == "sphere":
            center, radius = props.vector("center", np.zeros(3)), props.float("radius", 1.0)
            if not radius > 0:
                raise SceneError(self.path, props.line("radius"), f"sphere radius {radius} must be > 0",
                                 "give a positive radius (a zero radius is a zero-area shape)")
            s.to_world = s.to_world @ translate(center) @ scale([radius] * 3)
            lin = s.to_world[:3, :3]
            sv = np.linalg.svd(lin, compute_uv=False)
            if sv[-1] <= 1e-12 * max(sv[0], 1e-300):
                self._zero_area(node, where)
            if sv[0] - sv[-1] > 1e-9 * sv[0]:
                self.warnings.append(f"{self.path}:{node.line}: sphere to_world has non-uniform scaling "
                                     "(Mitsuba warns too and renders a sphere of the largest radius)")
        elif t in ("obj", "ply"):
            self._mesh(s, props, node, where)
        props.finish(SHAPE_PARAMS[t])
        if t in ("rectangle", "disk", "cube") and not _analytic_area(t, s.to_world) > 0:
            self._zero_area(node, where)
        return s

    def _zero_area(self, node, where):
        raise SceneError(self.path, node.line, f"{where} has zero area (a scale of 0 in to_world?)",
                         "give the shape a non-zero size")

    def _shape_children(self, s: Shape, nested, refs, where):
        bsdfs = []
        for n in nested:
            if n.tag == "bsdf":
                bsdfs.append((self.build(n, "bsdf"), n))
            elif n.tag == "emitter":
                if s.emitter is not None:
                    raise SceneError(self.path, n.line, "a shape has two emitters",
                                     "a shape carries at most one area emitter: remove the other")
                s.emitter = plugins.build_emitter(self, n, in_shape=True)
            elif n.tag == "medium":
                self._set_medium(s, n.attrs.get("name"), self.build(n, "medium"), n, where)
            else:
                self.no_children([n], where)
        for r in refs:
            target = self.decl.get(r.attrs["id"])
            if target is not None and target.tag == "medium":
                self._set_medium(s, r.attrs.get("name"), self.resolve(r, "medium"), r, where)
            else:
                bsdfs.append((self.resolve(r, "bsdf"), r))
        if len(bsdfs) > 1:
            raise SceneError(self.path, bsdfs[1][1].line, "a shape has more than one bsdf",
                             "a shape has exactly one bsdf: remove the others")
        if bsdfs:
            s.bsdf = bsdfs[0][0]
        elif s.emitter is not None:   # Mitsuba's default for an emitting shape: a black diffuse
            s.bsdf = BSDF(reflectance=rgb(0.0))
        else:                         # Mitsuba's default: diffuse, reflectance 0.5
            s.bsdf = BSDF()

    def _set_medium(self, s: Shape, name, medium, node, where):
        if name not in ("interior", "exterior"):
            raise SceneError(self.path, node.line, f"a medium inside {where} must be named interior or "
                             f"exterior (got {name!r})", f'write <ref name="interior" id="{medium.id}"/>')
        if getattr(s, name) is not None:
            raise SceneError(self.path, node.line, f"{where} sets its {name} medium twice",
                             f"give the {name} medium once")
        setattr(s, name, medium)

    def _mesh(self, s: Shape, props, node, where):
        fname = props.string("filename", None)
        if fname is None:
            raise SceneError(self.path, node.line, f"{where} has no filename",
                             f'add <string name="filename" value="meshes/x.{s.type}"/>')
        full = os.path.join(os.path.dirname(os.path.abspath(self.path)), fname)
        line = props.line("filename")
        if not os.path.isfile(full):
            raise SceneError(self.path, line, f"mesh file '{fname}' not found ({full})",
                             "give a path relative to the scene file's folder")
        try:
            V, F, N = (read_obj if s.type == "obj" else read_ply)(full)
        except MeshError as err:
            raise SceneError(self.path, line, err.message, err.fix) from None
        except (OSError, UnicodeDecodeError, ValueError) as err:
            raise SceneError(self.path, line, f"cannot read mesh '{fname}': {err}",
                             f"check that the file is a valid {s.type.upper()} file") from None
        if len(F) == 0 or len(V) == 0:
            raise SceneError(self.path, line, f"mesh '{fname}' is empty (no faces)",
                             "give a mesh with at least one triangle")
        s.face_normals = props.bool("face_normals", False)
        props.ignore("flip_tex_coords", self.warnings, "gdlearn has no textures")
        s.filename = full
        Vw, Nw = transform_mesh(V, N, s.to_world)
        area = triangle_areas(Vw, F)
        if not np.all(np.isfinite(Vw)) or not area.sum() > 0:
            self._zero_area(node, where)
        s.vertices, s.faces = Vw, F.astype(np.int32)
        if not s.face_normals:
            s.normals = Nw if Nw is not None else vertex_normals(Vw, F)


def _analytic_area(t: str, m: np.ndarray) -> float:
    """World-space area of a rectangle, disk or cube under the linear part of ``m``."""
    x, y, z = m[:3, 0], m[:3, 1], m[:3, 2]
    if t == "rectangle":
        return 4.0 * float(np.linalg.norm(np.cross(x, y)))
    if t == "disk":
        return np.pi * float(np.linalg.norm(np.cross(x, y)))
    return 8.0 * float(sum(np.linalg.norm(np.cross(a, b)) for a, b in ((x, y), (y, z), (z, x))))
