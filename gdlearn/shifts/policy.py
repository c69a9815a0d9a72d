"""Combined shift policies: which shift runs at each vertex of a base path (STAR, Hua et al. 2019,
Sec. 3.5 "Combined Shift Mapping", Sec. 4.1; Kettunen et al. 2015).

A policy walks the base path from the sensor. At vertex b (already shifted to x'_b) it looks at the
classes of x_b, x'_b and the next base vertex x_{b+1} and picks one action for the segment leaving b:

* ``SHIFT_RECONNECT`` -- x_b, x'_b and x_{b+1} are connectable: join x'_b to x_{b+1}; the rest of the
  path is shared (Sec. 3.3, Jacobian 1 in area);
* ``SHIFT_MANIFOLD`` -- x_b and x'_b connectable, then a specular chain of 1..MAX_CHAIN vertices ending
  at a connectable vertex x_c: move the chain so it joins x'_b to x_c (Sec. 3.4);
* ``SHIFT_HALFVECTOR`` -- copy the half vector at b (Sec. 3.2, Eq. 15) and trace on;
* ``SHIFT_REPLAY`` -- reuse the base path's random numbers at b (Sec. 3.1);
* ``SHIFT_FAIL`` -- the vertex classes of base and offset disagree (one connectable, the other not):
  the shift is not invertible there (Kettunen et al. 2015); weight 1 / zero offset (Sec. 3.5).

Policies (names for ``--shift``): ``replay``, ``replay+reconnection``, ``halfvector+reconnection``
and ``halfvector+reconnection+manifold``. The vertex classes come from ``bsdf.vertex_class(mat,
threshold)`` / ``lobe_class``, so the roughness threshold is configurable there.

The integrators count what ran in a stats vector indexed by the ``STAT_*`` constants below
(:func:`record`), so every frame can report which shifts ran, succeeded and failed.
"""
import numpy as np
from numba import njit

from gdlearn.kernels import layout as L
from gdlearn.shifts.reconnection import connectable

# --- policies --------------------------------------------------------------------------------
POLICY_REPLAY = 0
POLICY_REPLAY_RECONNECTION = 1
POLICY_HALFVECTOR_RECONNECTION = 2
POLICY_HALFVECTOR_RECONNECTION_MANIFOLD = 3

POLICIES = {"replay": POLICY_REPLAY,
            "replay+reconnection": POLICY_REPLAY_RECONNECTION,
            "halfvector+reconnection": POLICY_HALFVECTOR_RECONNECTION,
            "halfvector+reconnection+manifold": POLICY_HALFVECTOR_RECONNECTION_MANIFOLD}

# --- actions ---------------------------------------------------------------------------------
SHIFT_REPLAY = 0
SHIFT_HALFVECTOR = 1
SHIFT_RECONNECT = 2
SHIFT_MANIFOLD = 3
SHIFT_FAIL = 4
ACTION_NAMES = ("replay", "halfvector", "reconnection", "manifold", "fail")

#: longest specular chain the manifold walk is asked to move (issue 7: chains of length 1-3).
MAX_CHAIN = 3

# --- statistics: counters[action * 3 + outcome] ------------------------------------------------
OUTCOME_RUN = 0
OUTCOME_OK = 1
OUTCOME_FAILED = 2
N_STATS = 5 * 3


def policy_code(name: str) -> int:
    """The policy constant for a ``--shift`` name; a clear error lists the valid names."""
    try:
        return POLICIES[name]
    except KeyError:
        raise ValueError(f"unknown shift policy {name!r}; fix: use one of "
                         f"{', '.join(sorted(POLICIES))}") from None


@njit(cache=True, error_model="numpy")
def specular_chain_end(vclass, start, n):
    """Index of the first connectable vertex at or after ``start`` (n if none): the chain
    x_start .. x_{end-1} is the run of specular vertices the manifold walk would move."""
    i = start
    while i < n and vclass[i] == L.V_SPECULAR:
        i += 1
    return i


@njit(cache=True, error_model="numpy")
def choose_shift(policy, class_b, class_b_offset, vclass_base, b, n):
    """The action for the segment leaving vertex b >= 1 (module docstring); the primary segment
    (sensor -> x_1) is shifted by the pixel offset itself, which the integrator does.

    ``vclass_base`` holds the base path's vertex classes (n valid vertices); ``class_b_offset`` is
    the class of the already shifted offset vertex x'_b.
    """
    cb = connectable(class_b)
    if cb != connectable(class_b_offset):
        return SHIFT_FAIL
    if policy == POLICY_REPLAY:
        return SHIFT_REPLAY
    if b + 1 >= n:
        # no next base vertex: the segment to a light sample (next-event estimation) is reconnected
        # from a connectable vertex; from a specular one it can only follow the copied direction
        if cb:
            return SHIFT_RECONNECT
        return SHIFT_REPLAY if policy == POLICY_REPLAY_RECONNECTION else SHIFT_HALFVECTOR
    nxt = vclass_base[b + 1]
    if cb and connectable(nxt):
        return SHIFT_RECONNECT
    if policy == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD and cb and nxt == L.V_SPECULAR:
        end = specular_chain_end(vclass_base, b + 1, n)
        if end < n and end - (b + 1) <= MAX_CHAIN:
            return SHIFT_MANIFOLD
    if policy == POLICY_REPLAY_RECONNECTION:
        return SHIFT_REPLAY
    return SHIFT_HALFVECTOR


@njit(cache=True, error_model="numpy")
def record(stats, action, ok):
    """Count one shift of ``action`` and its outcome in ``stats`` (int64[N_STATS])."""
    stats[action * 3 + OUTCOME_RUN] += 1
    if ok:
        stats[action * 3 + OUTCOME_OK] += 1
    else:
        stats[action * 3 + OUTCOME_FAILED] += 1


def new_stats():
    return np.zeros(N_STATS, np.int64)


def stats_dict(stats) -> dict:
    """{'reconnection': {'run': .., 'ok': .., 'failed': ..}, ...} for a Frame's stats."""
    stats = np.asarray(stats)
    return {name: {"run": int(stats[a * 3]), "ok": int(stats[a * 3 + 1]), "failed": int(stats[a * 3 + 2])}
            for a, name in enumerate(ACTION_NAMES)}
