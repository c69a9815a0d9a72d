"""Write the small triangle meshes the shipped scenes use (scenes/meshes/).

Run from the repository root:  python scripts/make_meshes.py
The output is deterministic (no random numbers), so re-running it reproduces the committed files
byte for byte.

* ``icosphere.obj``: a unit icosphere (2 subdivisions of the icosahedron: 162 vertices, 320 faces),
  written with ``v``, ``vt``, ``vn`` and ``f v/vt/vn`` records: it exercises the full OBJ face form.
* ``pedestal.obj``: a hexagonal prism whose sides are quads and whose caps are hexagons (``f v``
  and ``f v//vn`` polygon records), so a loader must triangulate polygons (fan triangulation, as
  Mitsuba 3's OBJ loader does for convex faces).
* ``blob.ply``: a lumpy "bunny-like" blob, an icosphere (3 subdivisions: 642 vertices, 1280 faces)
  whose radius varies smoothly with direction; binary_little_endian PLY with float x y z and
  ``list uchar int vertex_indices``.
* ``tetra.ply``: a tetrahedron as ASCII PLY (the other PLY encoding the loader reads).

Every face is wound counter-clockwise seen from outside, so geometric normals point outwards.
"""
from __future__ import annotations

import os
import struct

import numpy as np

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes", "meshes")


def icosahedron():
    t = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
                  [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                  [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                  [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                  [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    return v / np.linalg.norm(v, axis=1, keepdims=True), f


def subdivide(v, f):
    """Split every triangle into four; new vertices are edge midpoints pushed onto the unit sphere."""
    verts = [tuple(p) for p in v]
    cache: dict[tuple[int, int], int] = {}

    def mid(a, b):
        key = (min(a, b), max(a, b))
        if key not in cache:
            p = (v[a] + v[b]) / 2.0
            verts.append(tuple(p / np.linalg.norm(p)))
            cache[key] = len(verts) - 1
        return cache[key]

    out = []
    for a, b, c in f:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        v = np.asarray(verts)   # keep `mid` reading the grown array
    return np.asarray(verts), np.asarray(out, dtype=np.int64)


def icosphere(levels):
    v, f = icosahedron()
    for _ in range(levels):
        v, f = subdivide(v, f)
    return v, f


def write_icosphere_obj(path):
    v, f = icosphere(2)
    uv = np.stack([0.5 + np.arctan2(v[:, 2], v[:, 0]) / (2 * np.pi),
                   0.5 - np.arcsin(np.clip(v[:, 1], -1, 1)) / np.pi], axis=1)
    with open(path, "w") as fh:
        fh.write("# icosphere, 2 subdivisions, unit radius (scripts/make_meshes.py)\n")
        fh.writelines(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
        fh.writelines(f"vt {s:.6f} {t:.6f}\n" for s, t in uv)
        fh.writelines(f"vn {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
        fh.write("o icosphere\n")
        # OBJ indices are 1-based; v, vt and vn share the same index here
        fh.writelines(f"f {a+1}/{a+1}/{a+1} {b+1}/{b+1}/{b+1} {c+1}/{c+1}/{c+1}\n" for a, b, c in f)


def write_pedestal_obj(path):
    """Hexagonal prism, radius 1, y in [0, 1]: 6 quads and 2 hexagons (polygons to triangulate)."""
    ang = np.arange(6) * np.pi / 3.0
    ring = np.stack([np.cos(ang), np.zeros(6), -np.sin(ang)], axis=1)   # counter-clockwise from +y
    bottom, top = ring.copy(), ring + [0.0, 1.0, 0.0]
    with open(path, "w") as fh:
        fh.write("# hexagonal prism with quad sides and hexagonal caps (scripts/make_meshes.py)\n")
        fh.writelines(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in np.vstack([bottom, top]))
        fh.write("vn 0 1 0\nvn 0 -1 0\n")
        fh.write("f " + " ".join(f"{7 + i}//1" for i in range(6)) + "\n")          # top, faces +y
        fh.write("f " + " ".join(f"{1 + i}//2" for i in reversed(range(6))) + "\n")  # bottom, -y
        for i in range(6):
            j = (i + 1) % 6
            fh.write(f"f {1 + i} {1 + j} {7 + j} {7 + i}\n")                        # sides, outward


def write_blob_ply(path):
    v, f = icosphere(3)
    x, y, z = v.T
    # smooth lumps (low-order bumps) plus two Gaussian "ears" on top: a bunny-like silhouette
    ears = sum(np.exp(-((x - cx) ** 2 + z ** 2) / 0.04) for cx in (-0.35, 0.35))
    r = 1.0 + 0.12 * np.sin(3 * x) * np.cos(2 * z) + 0.5 * ears * np.clip(y, 0, None)
    p = (v * r[:, None]).astype("<f4")
    header = ("ply\nformat binary_little_endian 1.0\ncomment lumpy blob (scripts/make_meshes.py)\n"
              f"element vertex {len(p)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(p.tobytes())
        for a, b, c in f:
            fh.write(struct.pack("<Biii", 3, a, b, c))


def write_tetra_ply(path):
    v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64)
    f = [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]
    with open(path, "w") as fh:
        fh.write("ply\nformat ascii 1.0\ncomment tetrahedron (scripts/make_meshes.py)\n"
                 "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                 "element face 4\nproperty list uchar int vertex_indices\nend_header\n")
        fh.writelines(f"{a:g} {b:g} {c:g}\n" for a, b, c in v)
        fh.writelines(f"3 {a} {b} {c}\n" for a, b, c in f)


def main():
    os.makedirs(OUT, exist_ok=True)
    write_icosphere_obj(os.path.join(OUT, "icosphere.obj"))
    write_pedestal_obj(os.path.join(OUT, "pedestal.obj"))
    write_blob_ply(os.path.join(OUT, "blob.ply"))
    write_tetra_ply(os.path.join(OUT, "tetra.ply"))
    print("wrote", sorted(os.listdir(OUT)))


if __name__ == "__main__":
    main()
