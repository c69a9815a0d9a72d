"""Light paths as flat structure-of-arrays vertex records.

A photon map keeps more than (position, power, direction): the gradient-domain estimators (GPM,
Hua et al. 2017, Sec. 4.2; G-VPM, Gruson et al. 2018, Sec. 4.3) shift a photon by re-tracing or
reconnecting its light subpath, so they need the parent vertex, the sampled lobe and the
area-measure pdfs of every vertex (PHOTONS.md Sec. 1.2). Every vertex of every light path of a pass
is one row of :class:`LightPaths`; the vertices of one path are contiguous, vertex 0 (on the
emitter) first, and ``parent`` links each vertex to the previous one. A path that leaves the
scene from its emitter (no edge, no photon) is not recorded at all; it still counts in the
normalisation by the number of light paths emitted (``TraceParams.keep_escaped`` records them).

=============  ===========  =================================================================
field          dtype/shape  meaning
=============  ===========  =================================================================
pos            f64 (n, 3)   position
nrm            f64 (n, 3)   geometric normal (emitter: its normal; zeros for point and spot and
                            for medium vertices)
nsh            f64 (n, 3)   shading normal (zeros for medium vertices)
d_in           f64 (n, 3)   unit direction of travel of the edge that arrived here
                            (vertex 0: the emitted direction)
beta           f64 (n, 3)   power arriving here, per emitted light path: everything up to but
                            excluding this vertex's own scattering (vertex 0: Le / pdf). The
                            edge's free-flight weight is included: T / P(pass) at a surface,
                            sigma_s T / pdf(t) at a medium vertex (the albedo for grey media), so
                            medium photons carry sigma_s-weighted flux (Jarosz et al. 2008,
                            Eq. 4 and 11) and only the phase function is left to the estimator
pdf_fwd        f64 (n,)     density of this vertex given its parent, in the parent's sampling
                            measure carried to this vertex: solid-angle pdf (1 after a null
                            vertex, a delta's discrete probability after a delta lobe) x the
                            free-flight factor of the edge (collision density at a medium vertex,
                            P(pass) at a surface, 1 in vacuum) x ``|cos|`` (1 in a medium) / dist^2 --
                            area measure on surfaces, volume measure in media (PHOTONS.md Sec. 0.1,
                            E2); vertex 0: the area pdf of the position, emitter selection included
pdf_rev        f64 (n,)     the same density of the parent given this vertex, sampled backwards
                            (0 where not defined: delta lobes and null vertices, the path's last
                            vertex's parent)
kind           i8 (n,)      K_EMITTER, K_SURFACE, K_MEDIUM
obj            i32 (n,)     emitter row (K_EMITTER), material row (K_SURFACE), medium row
                            (K_MEDIUM)
prim           i32 (n,)     primitive hit (-1 for emitters without a shape and medium vertices)
lobe           i8 (n,)      class (layout.V_*) of the lobe sampled to leave (V_MEDIUM for a
                            phase sample); -1 if the path ended here or the vertex is a null
                            interface (a pass-through)
flags          i8 (n,)      F_DELTA_OUT: the outgoing sample was a Dirac delta (null vertices
                            too: the direction is kept); F_PHOTON: stored as a photon;
                            F_DELTA_POS / F_DELTA_DIR on vertex 0 for delta lights
parent         i32 (n,)     row of the previous vertex (-1 at vertex 0)
path           i64 (n,)     light-path index j (the random-number key is LIGHT_KEY0 + j)
depth          i32 (n,)     scattering vertices of the path up to and including this one
                            (0 = on the emitter); a null vertex, not a bounce, takes the depth
                            of the scattering vertex its edge is heading for (parent's + 1)
medium         i16 (n,)     medium row of the edge that arrived here (-1 vacuum); vertex 0: the
                            medium the emitter sits in
=============  ===========  =================================================================

Null interfaces (``null`` BSDF, a medium's boundary) are recorded as K_SURFACE vertices with
lobe -1 and F_DELTA_OUT, never photons. So every edge parent -> vertex lies in one medium,
``medium[vertex]``: an edge with ``medium >= 0`` is a photon beam (PHOTONS.md Sec. 1.2, a short
beam ending at the sampled vertex), and the null vertices are there for the gradient shifts that
must cross the same interfaces (Gruson et al. 2018, Sec. 4.3). A beam's flux, the power after the
parent's scattering without the edge's own transmittance, is ``beta[vertex]`` divided by the edge's
free-flight weight: the albedo at a medium vertex and 1 elsewhere in a grey medium.

Photons are the rows with F_PHOTON: surface vertices (depth >= 1) whose material has a non-delta,
connectable lobe, and, when the tracer is asked for them (``TraceParams.want_volume``), every medium
vertex (PHOTONS.md Sec. 1.2: "one photon per medium vertex"). The normalisation of any estimate is
by the number of light paths *emitted*, including those that stored nothing.
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
    medium: np.ndarray

    def __len__(self) -> int:       # the number of vertices (a NamedTuple's len would be 16)
        return int(self.pos.shape[0])

    @property
    def photons(self) -> np.ndarray:
        """Rows that are stored photons, in row order (deterministic)."""
        return np.flatnonzero(self.flags & F_PHOTON).astype(np.int64)

    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self))


def allocate(n: int, empty: bool = False) -> LightPaths:
    """Records for ``n`` vertices: ``kind`` = -1 marks unused slots, or, with ``empty``, left
    uninitialised for a writer that fills every field of every row (the compaction)."""
    shape = lambda w: (n, 3) if w == 3 else n   # noqa: E731
    if empty:
        return LightPaths(*(np.empty(shape(w), dtype=t) for t, w, _ in FIELDS))
    return LightPaths(*(np.full(shape(w), fill, dtype=t) for t, w, fill in FIELDS))


#: (dtype, width, value of an unused slot) of every field, in LightPaths order
FIELDS = (("f8", 3, 0.0), ("f8", 3, 0.0), ("f8", 3, 0.0), ("f8", 3, 0.0), ("f8", 3, 0.0), ("f8", 1, 0.0),
          ("f8", 1, 0.0), ("i1", 1, -1), ("i4", 1, -1), ("i4", 1, -1), ("i1", 1, -1), ("i1", 1, 0),
          ("i4", 1, -1), ("i8", 1, 0), ("i4", 1, 0), ("i2", 1, -1))
BYTES_PER_VERTEX = sum(np.dtype(t).itemsize * w for t, w, _ in FIELDS)
