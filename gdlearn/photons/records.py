"""Light paths as flat structure-of-arrays vertex records.

A photon map keeps more than (position, power, direction): the gradient-domain estimators (GPM,
Hua et al. 2017, Sec. 4.2; G-VPM, Gruson et al. 2018, Sec. 4.3) shift a photon by re-tracing or
reconnecting its light subpath, so they need the parent vertex, the sampled lobe and the
area-measure pdfs of every vertex (PHOTONS.md Sec. 1.2). Every vertex of every light path of a pass
is one row of :class:`LightPaths`; the vertices of one path are contiguous, vertex 0 (on the
emitter) first, and ``parent`` links each vertex to the previous one.

=============  ===========  =================================================================
field          dtype/shape  meaning
=============  ===========  =================================================================
pos            f64 (n, 3)   position
nrm            f64 (n, 3)   geometric normal (emitter: its normal; zeros for point and spot)
nsh            f64 (n, 3)   shading normal
d_in           f64 (n, 3)   unit direction of travel of the edge that arrived here
                            (vertex 0: the emitted direction)
beta           f64 (n, 3)   power arriving here, per emitted light path: everything up to but
                            excluding this vertex's own scattering (vertex 0: Le / pdf)
pdf_fwd        f64 (n,)     area-measure pdf of this vertex given its parent (vertex 0: of the
                            position, emitter selection included); a delta's discrete probability
pdf_rev        f64 (n,)     area-measure pdf of the parent given this vertex, sampled backwards
                            (0 where not defined: delta lobes, the path's last vertex's child)
kind           i8 (n,)      K_EMITTER, K_SURFACE (K_MEDIUM reserved for the volume estimators)
obj            i32 (n,)     emitter row (K_EMITTER), material row (K_SURFACE)
prim           i32 (n,)     primitive hit (-1 for emitters without a shape)
lobe           i8 (n,)      class (layout.V_*) of the lobe sampled to leave; -1 if the path ended
                            here or the interface is a null pass-through
flags          i8 (n,)      F_DELTA_OUT: the outgoing sample was a Dirac delta; F_PHOTON: stored
                            as a photon; F_DELTA_POS / F_DELTA_DIR on vertex 0 for delta lights
parent         i32 (n,)     row of the previous vertex (-1 at vertex 0)
path           i64 (n,)     light-path index j (the random-number key is LIGHT_KEY0 + j)
depth          i32 (n,)     vertex index inside its path (0 = on the emitter)
=============  ===========  =================================================================

Photons are the rows with F_PHOTON: surface vertices (depth >= 1) whose material has a non-delta,
connectable lobe (PHOTONS.md Sec. 1.2). The normalisation of any estimate is by the number of
light paths *emitted*, including those that stored nothing.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

K_EMITTER, K_SURFACE, K_MEDIUM = 0, 1, 2
F_DELTA_OUT, F_PHOTON, F_DELTA_POS, F_DELTA_DIR = 1, 2, 4, 8


class LightPaths(NamedTuple):
    pos: np.ndarray
    nrm: np.ndarray
    nsh: np.ndarray
    d_in: np.ndarray
    beta: np.ndarray
    pdf_fwd: np.ndarray
    pdf_rev: np.ndarray
    kind: np.ndarray
    obj: np.ndarray
    prim: np.ndarray
    lobe: np.ndarray
    flags: np.ndarray
    parent: np.ndarray
    path: np.ndarray
    depth: np.ndarray

    def __len__(self) -> int:       # the number of vertices (a NamedTuple's len would be 15)
        return int(self.pos.shape[0])

    @property
    def photons(self) -> np.ndarray:
        """Rows that are stored photons, in row order (deterministic)."""
        return np.flatnonzero(self.flags & F_PHOTON).astype(np.int64)

    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self))


def allocate(n: int) -> LightPaths:
    """Uninitialised records for ``n`` vertices (``kind`` = -1 marks unused slots)."""
    f3 = lambda: np.zeros((n, 3))   # noqa: E731
    return LightPaths(f3(), f3(), f3(), f3(), f3(), np.zeros(n), np.zeros(n), np.full(n, -1, np.int8),
                      np.full(n, -1, np.int32), np.full(n, -1, np.int32), np.full(n, -1, np.int8),
                      np.zeros(n, np.int8), np.full(n, -1, np.int32), np.zeros(n, np.int64),
                      np.zeros(n, np.int32))


def concatenate(parts: list[LightPaths]) -> LightPaths:
    """Records of several batches as one, parents re-indexed to the concatenated rows."""
    if not parts:
        return allocate(0)
    offs = np.cumsum([0] + [len(p) for p in parts[:-1]])
    fields = []
    for k, name in enumerate(LightPaths._fields):
        if name == "parent":
            fields.append(np.concatenate([np.where(p.parent >= 0, p.parent + o, -1).astype(np.int32)
                                          for p, o in zip(parts, offs)]))
        else:
            fields.append(np.concatenate([p[k] for p in parts]))
    return LightPaths(*fields)


BYTES_PER_VERTEX = sum(np.dtype(t).itemsize * w for t, w in (
    ("f8", 3), ("f8", 3), ("f8", 3), ("f8", 3), ("f8", 3), ("f8", 1), ("f8", 1), ("i1", 1), ("i4", 1),
    ("i4", 1), ("i1", 1), ("i1", 1), ("i4", 1), ("i8", 1), ("i4", 1)))
