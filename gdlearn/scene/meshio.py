"""Triangle meshes from OBJ and PLY files, parsed with numpy (no mesh library).

What Mitsuba 3's ``obj`` and ``ply`` shapes read (src/shapes/obj.cpp, ply.cpp), restricted to what
the renderer needs:

* OBJ: ``v x y z``, ``vn``, ``vt`` and ``f`` records with ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``
  corners (1-based; Mitsuba reads no negative, relative indices, so they are an error here);
  polygons are fan-triangulated
  (``f a b c d`` -> ``a b c``, ``a c d``). Other records (``o``, ``g``, ``s``, ``usemtl``, ``mtllib``)
  are ignored.
* PLY: ``format ascii 1.0`` or ``binary_little_endian 1.0``; element ``vertex`` with float/double
  ``x y z`` (and optional ``nx ny nz``); element ``face`` with ``list <uchar|int|...> <int|uint>
  vertex_indices`` (or ``vertex_index``) holding triangles only: Mitsuba's PLY loader refuses
  other polygons ("is this a triangle mesh?"), so gdlearn does too, with a fix.

Functions raise :class:`MeshError` (a plain message and fix); the loader turns it into a
:class:`~gdlearn.scene.model.SceneError` at the line of the ``<shape>``.
"""
from __future__ import annotations

import numpy as np


class MeshError(Exception):
    def __init__(self, message: str, fix: str):
        super().__init__(message)
        self.message, self.fix = message, fix


def read_obj(filename: str):
    """Return ``(positions V x 3, faces F x 3 int64, normals V x 3 or None)``.

    Corners that share a position but carry different ``vn`` normals are split so that per-vertex
    normals stay exact (as Mitsuba does); without ``vn`` the position index is the vertex index.
    """
    pos, nrm, corners_per_face = [], [], []
    with open(filename, "r", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            tok = line.split()
            if not tok:
                continue
            key = tok[0]
            try:
                if key == "v":
                    pos.append((float(tok[1]), float(tok[2]), float(tok[3])))
                elif key == "vn":
                    nrm.append((float(tok[1]), float(tok[2]), float(tok[3])))
                elif key == "f":
                    corners_per_face.append((lineno, [_obj_corner(c) for c in tok[1:]]))
            except (ValueError, IndexError):
                raise MeshError(f"{filename}:{lineno}: cannot parse OBJ record '{line.strip()}'",
                                "write 'v x y z' and 'f i j k' (i, i/t, i//n or i/t/n corners)") from None
    P = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
    N = np.asarray(nrm, dtype=np.float64).reshape(-1, 3)
    keys: dict[tuple[int, int], int] = {}
    tris = []
    use_n = len(N) > 0
    for lineno, corners in corners_per_face:
        if len(corners) < 3:
            raise MeshError(f"{filename}:{lineno}: a face needs at least 3 corners",
                            "remove the degenerate 'f' record")
        ids = []
        for vi, ni in corners:
            vi = _resolve(vi, len(P), filename, lineno, "vertex")
            ni = _resolve(ni, len(N), filename, lineno, "normal") if (use_n and ni is not None) else -1
            k = (vi, ni) if use_n else (vi, -1)
            if k not in keys:
                keys[k] = len(keys)
            ids.append(keys[k])
        for j in range(1, len(ids) - 1):       # fan triangulation of a (convex) polygon
            tris.append((ids[0], ids[j], ids[j + 1]))
    order = sorted(keys.items(), key=lambda kv: kv[1])
    vi = np.array([k[0] for k, _ in order], dtype=np.int64)
    ni = np.array([k[1] for k, _ in order], dtype=np.int64)
    V = P[vi] if len(vi) else np.zeros((0, 3))
    normals = N[ni] if (use_n and len(ni) and np.all(ni >= 0)) else None
    return V, np.asarray(tris, dtype=np.int64).reshape(-1, 3), normals


def _obj_corner(text: str):
    parts = text.split("/")
    v = int(parts[0])
    n = int(parts[2]) if len(parts) >= 3 and parts[2] else None
    return v, n


def _resolve(i: int, n: int, filename: str, lineno: int, what: str) -> int:
    if i < 0:
        raise MeshError(f"{filename}:{lineno}: negative (relative) {what} index {i}: Mitsuba's OBJ "
                        "loader does not support them", "write absolute 1-based indices")
    j = i - 1
    if not 0 <= j < n:
        raise MeshError(f"{filename}:{lineno}: {what} index {i} is out of range (1..{n})",
                        "fix the face record or the number of 'v'/'vn' records")
    return j


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _ply_header(fh, filename):
    if fh.readline().strip() != b"ply":
        raise MeshError(f"{filename}: not a PLY file (first line is not 'ply')", "write a PLY file")
    fmt, elements = None, []
    while True:
        raw = fh.readline()
        if not raw:
            raise MeshError(f"{filename}: PLY header has no end_header", "complete the PLY header")
        tok = raw.decode("ascii", "replace").split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "end_header":
            return fmt, elements
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property":
            if tok[1] == "list":
                elements[-1][2].append((tok[4], ("list", _ply_t(tok[2], filename), _ply_t(tok[3], filename))))
            else:
                elements[-1][2].append((tok[2], _ply_t(tok[1], filename)))


def _ply_t(name, filename):
    if name not in _PLY_TYPES:
        raise MeshError(f"{filename}: unknown PLY property type '{name}'",
                        "use float/double for coordinates and uchar/int for lists")
    return _PLY_TYPES[name]


def read_ply(filename: str):
    """Return ``(positions V x 3, faces F x 3 int64, normals V x 3 or None)``."""
    with open(filename, "rb") as fh:
        fmt, elements = _ply_header(fh, filename)
        if fmt not in ("ascii", "binary_little_endian"):
            raise MeshError(f"{filename}: PLY format '{fmt}' is not supported",
                            "save it as ascii or binary_little_endian")
        body = fh.read()
    data = {}
    if fmt == "ascii":
        words = body.split()
        at = 0
        for name, count, props in elements:
            rows, at = _ply_ascii_element(words, at, count, props, filename, name)
            data[name] = rows
    else:
        at = 0
        for name, count, props in elements:
            rows, at = _ply_binary_element(body, at, count, props, filename, name)
            data[name] = rows
    return _ply_mesh(data, filename)


def _ply_ascii_element(words, at, count, props, filename, name):
    out = {p: [] for p, _ in props}
    try:
        for _ in range(count):
            for pname, ptype in props:
                if isinstance(ptype, tuple):
                    n = int(words[at]); at += 1
                    out[pname].append([int(w) for w in words[at:at + n]]); at += n
                else:
                    out[pname].append(float(words[at])); at += 1
    except (IndexError, ValueError):
        raise MeshError(f"{filename}: PLY element '{name}' is truncated or malformed",
                        "the file has fewer values than its header declares") from None
    return out, at


def _ply_binary_element(body, at, count, props, filename, name):
    if all(not isinstance(t, tuple) for _, t in props):
        dt = np.dtype([(p, "<" + t) for p, t in props])
        if at + dt.itemsize * count > len(body):
            raise MeshError(f"{filename}: PLY element '{name}' is truncated", "re-export the file")
        arr = np.frombuffer(body, dtype=dt, count=count, offset=at)
        return {p: arr[p].astype(np.float64) for p, _ in props}, at + dt.itemsize * count
    if len(props) != 1:
        raise MeshError(f"{filename}: PLY element '{name}' mixes lists and scalars",
                        "keep only vertex_indices in the face element")
    pname, (_, ct, it) = props[0]
    ct_, it_ = np.dtype("<" + ct), np.dtype("<" + it)
    if count and at + ct_.itemsize <= len(body):   # fast path: every face a triangle
        n0 = int(np.frombuffer(body, ct_, 1, at)[0])
        dt = np.dtype([("n", ct_), ("v", it_, (n0,))])
        if at + dt.itemsize * count <= len(body):
            arr = np.frombuffer(body, dt, count, at)
            if np.all(arr["n"] == n0):
                return {pname: arr["v"].astype(np.int64)}, at + dt.itemsize * count
    rows = []
    try:
        for _ in range(count):
            n = int(np.frombuffer(body, ct_, 1, at)[0]); at += ct_.itemsize
            rows.append(np.frombuffer(body, it_, n, at).astype(np.int64).tolist()); at += n * it_.itemsize
    except ValueError:
        raise MeshError(f"{filename}: PLY element '{name}' is truncated", "re-export the file") from None
    return {pname: rows}, at


def _ply_mesh(data, filename):
    vert = data.get("vertex", {})
    if not all(k in vert for k in "xyz"):
        raise MeshError(f"{filename}: PLY has no vertex x, y, z", "export vertex positions x y z")
    V = np.stack([np.asarray(vert[k], dtype=np.float64) for k in "xyz"], axis=1).reshape(-1, 3)
    normals = None
    if all(k in vert for k in ("nx", "ny", "nz")):
        normals = np.stack([np.asarray(vert[k], dtype=np.float64) for k in ("nx", "ny", "nz")], axis=1)
    face = data.get("face", {})
    idx = face.get("vertex_indices", face.get("vertex_index"))
    if idx is None:
        return V, np.zeros((0, 3), dtype=np.int64), normals
    if isinstance(idx, np.ndarray) and idx.ndim == 2 and idx.shape[1] == 3:
        F = idx
    else:
        sizes = {len(f) for f in idx}
        if sizes - {3}:
            raise MeshError(f"{filename}: PLY faces with {sorted(sizes - {3})} vertices; Mitsuba's PLY "
                            "loader reads triangles only", "triangulate the mesh (or save it as OBJ, "
                            "whose polygons are triangulated on load)")
        F = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise MeshError(f"{filename}: a face index is out of range (0..{len(V) - 1})",
                        "fix the face list or the vertex count")
    return V, F, normals


def transform_mesh(V, normals, to_world):
    """World-space positions (affine) and normals (inverse transpose, renormalised)."""
    Vw = V @ to_world[:3, :3].T + to_world[:3, 3]
    Nw = None
    if normals is not None:
        Nw = normals @ np.linalg.inv(to_world[:3, :3])   # (M^-T n)^T = n^T M^-1
        Nw = Nw / np.maximum(np.linalg.norm(Nw, axis=1, keepdims=True), 1e-300)
    return Vw, Nw


def triangle_areas(V, F) -> np.ndarray:
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)


def vertex_normals(V, F) -> np.ndarray:
    """Smooth normals, each face normal weighted by its corner angle (Mitsuba's
    ``Mesh::recompute_vertex_normals``, after Max 1999 / Meyer et al. 2003)."""
    N = np.zeros_like(V)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    fn = fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    for k in range(3):
        a, b, c = V[F[:, k]], V[F[:, (k + 1) % 3]], V[F[:, (k + 2) % 3]]
        u, w = b - a, c - a
        u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
        w = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
        ang = np.arccos(np.clip(np.einsum("ij,ij->i", u, w), -1.0, 1.0))
        np.add.at(N, F[:, k], fn * ang[:, None])
    n = np.linalg.norm(N, axis=1, keepdims=True)
    return np.where(n > 0, N / np.maximum(n, 1e-300), np.array([0.0, 0.0, 1.0]))
