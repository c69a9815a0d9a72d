"""Reading a Mitsuba 3 XML file: elements with line numbers, ``$name`` substitution, typed values.

The first stage of :func:`gdlearn.scene.load.load`. It knows XML and Mitsuba's *value* tags
(``float``, ``integer``, ``boolean``, ``string``, ``rgb``, ``point``, ``vector``) but no plugin:
:class:`Props` collects one plugin element's parameters and hands them out typed, remembering which
were read so the loader can reject the ones nobody asked for (Mitsuba 3 rejects unreferenced
properties the same way). Every failure is a :class:`~gdlearn.scene.model.SceneError` naming the file
and line of the element at fault.

Mitsuba 3 semantics followed here (its XML scene format docs, "Scene file format"):
* ``<default name="x" value="v"/>`` declares a parameter; ``load(path, x=...)`` overrides it; ``$x``
  in any attribute is replaced by its value. A ``$x`` with neither is an error.
* ``rgb`` takes one value (grey) or three; ``point``/``vector`` take ``x``/``y``/``z`` (missing = 0)
  or ``value="x, y, z"``; ``boolean`` is ``true``/``false``.
"""
from __future__ import annotations

import re
import xml.parsers.expat
from dataclasses import dataclass, field

import numpy as np

from gdlearn.scene.model import SceneError

VALUE_TAGS = ("float", "integer", "boolean", "string", "rgb", "point", "vector")
_SUBST = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


@dataclass
class Node:
    """One XML element: tag, attributes, children and the line it starts on."""
    tag: str
    attrs: dict
    line: int
    children: list = field(default_factory=list)


def parse_xml(path: str) -> Node:
    """Parse ``path`` into a tree of :class:`Node` keeping each element's line (expat)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as err:
        raise SceneError(path, None, f"cannot read the scene file ({err.strerror})",
                         "check the path; scene files are Mitsuba 3 XML (see scenes/README.md)") from None
    parser = xml.parsers.expat.ParserCreate()
    stack: list[Node] = [Node("#document", {}, 1)]

    def start(tag, attrs):
        node = Node(tag, dict(attrs), parser.CurrentLineNumber)
        stack[-1].children.append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as err:
        raise SceneError(path, err.lineno, f"malformed XML: {xml.parsers.expat.ErrorString(err.code)}",
                         "fix the XML syntax at that line (unclosed tag, stray '<' or '&', bad quote)"
                         ) from None
    roots = stack[0].children
    return roots[0]


def collect_defaults(path: str, root: Node, overrides: dict) -> dict:
    """The ``<default>`` parameters of the scene, with keyword ``overrides`` applied (as strings)."""
    params: dict[str, str] = {}
    for node in root.children:
        if node.tag != "default":
            continue
        unknown = set(node.attrs) - {"name", "value"}
        if "name" not in node.attrs or "value" not in node.attrs or unknown:
            raise SceneError(path, node.line, "<default> needs exactly the attributes name and value",
                             'write <default name="res" value="256"/>')
        params[node.attrs["name"]] = node.attrs["value"]
    for key, val in overrides.items():
        params[key] = _format_override(val)
    return params


def _format_override(val) -> str:
    if isinstance(val, bool):
        return "true" if val else "false"
    if isinstance(val, (list, tuple, np.ndarray)):
        return ", ".join(repr(float(x)) for x in val)
    return str(val)


def substitute(path: str, node: Node, params: dict) -> None:
    """Replace every ``$name`` in the attributes of ``node`` and its descendants (in place)."""
    for key, val in node.attrs.items():
        if "$" not in val:
            continue

        def repl(match, _line=node.line):
            name = match.group(1)
            if name not in params:
                raise SceneError(path, _line, f"'${name}' has no value",
                                 f'declare <default name="{name}" value="..."/> at the top of the scene '
                                 f"or pass load(path, {name}=...)")
            return params[name]

        node.attrs[key] = _SUBST.sub(repl, val)
    for child in node.children:
        substitute(path, child, params)


def _floats(path, node, text, what) -> list[float]:
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        return [float(p) for p in parts]
    except ValueError:
        raise SceneError(path, node.line, f"{what}: '{text}' is not a list of numbers",
                         "write numbers separated by commas, e.g. value=\"0.5, 0.5, 0.5\"") from None


def parse_value(path: str, node: Node):
    """The Python value of a value element (``<float name=... value=...>`` etc.)."""
    tag, a = node.tag, node.attrs
    name = a.get("name")
    what = f"<{tag} name=\"{name}\">"
    if tag in ("point", "vector"):
        allowed = {"name", "value", "x", "y", "z"}
        _check_attrs(path, node, allowed)
        if "value" in a:
            v = _floats(path, node, a["value"], what)
            if len(v) == 1:
                v = v * 3
        else:
            v = [_float(path, node, a.get(k, "0"), what) for k in ("x", "y", "z")]
        if len(v) != 3:
            raise SceneError(path, node.line, f"{what} needs 3 components, got {len(v)}",
                             'write x="..." y="..." z="..." or value="x, y, z"')
        return np.array(v, dtype=np.float64)
    _check_attrs(path, node, {"name", "value"})
    if "value" not in a:
        raise SceneError(path, node.line, f"{what} has no value attribute", f'add value="..." to {what}')
    text = a["value"]
    if tag == "float":
        return _float(path, node, text, what)
    if tag == "integer":
        try:
            return int(text.strip())
        except ValueError:
            raise SceneError(path, node.line, f"{what}: '{text}' is not an integer",
                             "write a whole number (use <float> for fractional values)") from None
    if tag == "boolean":
        low = text.strip().lower()
        if low not in ("true", "false"):
            raise SceneError(path, node.line, f"{what}: '{text}' is not a boolean",
                             'write value="true" or value="false"')
        return low == "true"
    if tag == "string":
        return text
    if tag == "rgb":
        v = _floats(path, node, text, what)
        if len(v) not in (1, 3):
            raise SceneError(path, node.line, f"{what} needs one or three values, got {len(v)}",
                             'write value="r, g, b" (or one value for grey)')
        return np.array(v * 3 if len(v) == 1 else v, dtype=np.float64)
    raise AssertionError(tag)


def _float(path, node, text, what) -> float:
    try:
        x = float(text.strip())
    except ValueError:
        raise SceneError(path, node.line, f"{what}: '{text}' is not a number",
                         "write a decimal number, e.g. value=\"0.5\"") from None
    if not np.isfinite(x):
        raise SceneError(path, node.line, f"{what}: '{text}' is not finite", "write a finite number")
    return x


def _check_attrs(path, node, allowed):
    extra = sorted(set(node.attrs) - set(allowed))
    if extra:
        raise SceneError(path, node.line, f"<{node.tag}> has unknown attribute(s) {', '.join(extra)}",
                         f"<{node.tag}> takes only {', '.join(sorted(allowed))}")


@dataclass
class Param:
    tag: str
    value: object
    node: Node


class Props:
    """The parameters of one plugin element, read by name and type; unread ones are errors.

    ``where`` names the plugin in messages, e.g. ``<bsdf type="diffuse">``.
    """

    def __init__(self, path: str, node: Node, where: str):
        self.path, self.node, self.where = path, node, where
        self.params: dict[str, Param] = {}
        self.used: set[str] = set()

    def add(self, node: Node):
        name = node.attrs.get("name")
        if not name:
            raise SceneError(self.path, node.line, f"<{node.tag}> inside {self.where} has no name",
                             f'add name="..." (the parameter of {self.where} it sets)')
        if name in self.params:
            raise SceneError(self.path, node.line, f"parameter '{name}' of {self.where} is set twice",
                             "remove one of the two definitions")
        self.params[name] = Param(node.tag, parse_value(self.path, node), node)

    def has(self, name: str) -> bool:
        return name in self.params

    def line(self, name: str) -> int:
        return self.params[name].node.line if name in self.params else self.node.line

    def _get(self, name, default, tags, kind):
        if name not in self.params:
            return default
        self.used.add(name)
        p = self.params[name]
        if p.tag not in tags:
            raise SceneError(self.path, p.node.line,
                             f"parameter '{name}' of {self.where} must be {kind}, got <{p.tag}>",
                             f'write <{tags[0]} name="{name}" value="..."/>')
        return p.value

    def float(self, name, default=None):
        v = self._get(name, default, ("float", "integer"), "a <float>")
        return None if v is None else float(v)

    def int(self, name, default=None):
        return self._get(name, default, ("integer",), "an <integer>")

    def bool(self, name, default=None):
        return self._get(name, default, ("boolean",), "a <boolean>")

    def string(self, name, default=None):
        return self._get(name, default, ("string",), "a <string>")

    def color(self, name, default):
        """An RGB colour: ``<rgb>`` or a ``<float>`` (grey), as Mitsuba accepts both for spectra."""
        v = self._get(name, None, ("rgb", "float", "integer"), "an <rgb> (or <float>)")
        if v is None:
            return np.array(np.broadcast_to(np.asarray(default, dtype=np.float64), 3))
        return np.full(3, float(v)) if np.ndim(v) == 0 else np.asarray(v, dtype=np.float64)

    def vector(self, name, default=None):
        return self._get(name, default, ("point", "vector"), "a <point> or <vector>")

    def ignore(self, name: str, warnings: list, why: str):
        """Accept a parameter gdlearn does not use, with a warning in ``Scene.warnings``."""
        if name in self.params:
            self.used.add(name)
            warnings.append(f"{self.path}:{self.line(name)}: {self.where} parameter '{name}' "
                            f"is ignored by gdlearn ({why})")

    def finish(self, known: tuple):
        """Error on the first parameter no builder read (Mitsuba: "unreferenced property")."""
        for name, p in self.params.items():
            if name not in self.used:
                raise SceneError(self.path, p.node.line,
                                 f"{self.where} has no parameter '{name}' (in gdlearn's subset)",
                                 f"remove it; {self.where} takes: {', '.join(known) or 'no parameters'}"
                                 " (see scenes/README.md)")
