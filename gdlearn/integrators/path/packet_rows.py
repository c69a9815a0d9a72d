"""The packet path tracer's state: which quantity of a lane lives in which row of ``S`` (float64)
and ``Q`` (int64), the item table, and the buffers of a row (:mod:`gdlearn.integrators.path.packet`).

Element ``S[r * PK + j]`` is row r of lane j (:mod:`gdlearn.kernels.accel.packet`: a constant row
stride lets the compiler prove that rows do not overlap, and vectorise a loop over the lanes). The
traversal's own rows come first.
"""
import numpy as np

from gdlearn.kernels.accel.packet import N_Q_TRACE, N_S_TRACE, PK
from gdlearn.kernels.jit import block, leaf

# float rows (after the traversal's): the ray set of the next closest hit, the shadow ray set,
# throughput, radiance, beta * next-event term waiting for its shadow ray, previous vertex, its pdf, eta
R_O = N_S_TRACE
R_SO = R_O + 7
R_BETA = R_SO + 7
R_L = R_BETA + 3
R_C = R_L + 3
R_PP = R_C + 3
R_PPDF = R_PP + 3
R_ETA = R_PPDF + 1
R_UEM = R_ETA + 1       # 3: this bounce's random numbers for the emitter sample
R_WO = R_UEM + 3        # 3: its cosine-weighted direction (local frame) for the BSDF sample
R_URR = R_WO + 3        # its Russian-roulette number
R_UBSDF = R_URR + 1     # 3: its BSDF sample's numbers (lobe, direction) for other BSDFs than diffuse
# the vertex: point, normals, shading frame, wi (local)
R_P, R_NG, R_NS, R_FS, R_FT, R_WI = (R_UBSDF + 3 + 3 * k for k in range(6))
# a diffuse vertex's material, gathered for the SIMD loops over the lanes: reflectance, twosided flag
R_MREF = R_WI + 3
R_M2S = R_MREF + 3
# a diffuse lane's area-emitter sample, gathered for packet_nee.nee_diffuse_area: the triangle's p0,
# e1, e2, its normal, the emitter's rgb, its area pdf
R_EP0 = R_M2S + 1
R_ENG = R_EP0 + 9
R_ERGB = R_ENG + 3
R_EPA = R_ERGB + 3
N_S = R_EPA + 1
# int rows (after the traversal's): path state, bounce, item (-1: idle lane), previous vertex delta,
# path goes on after this bounce, a next-event term is pending
Q_H = N_Q_TRACE
Q_DEPTH, Q_ITEM, Q_DELTA, Q_ALIVE, Q_NEE = Q_H + 1, Q_H + 2, Q_H + 3, Q_H + 4, Q_H + 5
Q_MAT, Q_CONT = Q_H + 6, Q_H + 7        # the vertex's material row; the bounce scatters at the vertex
Q_EMP = Q_H + 8                         # a deferred next-event estimate's triangle (-1: none)
Q_DIFF = Q_H + 9                        # the vertex is diffuse: its BSDF sample is deferred
N_Q = Q_DIFF + 1

#: items (pixel, sample) whose radiance a row keeps before summing them per pixel
N_ITEMS = 4096


#: columns of the item table: film position x, y (raster), the pixel key and sample index whose
#: random numbers the path uses (for random-sequence replay, another pixel's than the film position's)
IT_FX, IT_FY, IT_KEY, IT_S = range(4)


@block
def new_buffers():
    """A row's packet state (S, Q), item radiances and item table (N_ITEMS x 4, float64: every
    integer in it is far below 2^53)."""
    return (np.zeros(N_S * PK), np.zeros(N_Q * PK, dtype=np.int64), np.zeros(3 * N_ITEMS),
            np.zeros((N_ITEMS, 4)))


@leaf
def get3(S, r, j):
    return (S[r * PK + j], S[(r + 1) * PK + j], S[(r + 2) * PK + j])


@leaf
def set3(S, r, j, v):
    S[r * PK + j], S[(r + 1) * PK + j], S[(r + 2) * PK + j] = v[0], v[1], v[2]


@leaf
def set_if(S, r, j, ok, v):
    """Row r of lane j becomes v where ``ok``, else stays: a select and a store, no branch (the SIMD
    loops over the lanes)."""
    S[r * PK + j] = v if ok else S[r * PK + j]


@leaf
def set3_if(S, r, j, ok, v):
    """:func:`set_if` of rows r, r+1, r+2 (a 3-vector)."""
    set_if(S, r, j, ok, v[0])
    set_if(S, r + 1, j, ok, v[1])
    set_if(S, r + 2, j, ok, v[2])
