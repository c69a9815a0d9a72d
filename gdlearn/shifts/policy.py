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

Policies (names for ``--shift``): ``replay``, ``replay+reconnection``, ``halfvector+reconnection``,
``halfvector+reconnection+manifold`` and ``halfvector+replay+reconnection``. The vertex classes come
from ``bsdf.vertex_class(mat, threshold)`` / ``lobe_class``, so the roughness threshold is
configurable there; the class of a *base* vertex is the class of the lobe its sampled direction
belongs to as a function of the path (``lobe_class``: specular for a delta direction, else the
material's class), never the random lobe choice of a rough plastic, whose two non-delta lobes can
both produce the same direction: a decision that depended on that choice would not be a function of
the path, and the inverse shift, which sees only the path, could not repeat it.

Reversibility (STAR Sec. 3.5, Fig. 4). Eq. 17's weights of a forward shift T and of the backward
shift of the same pair sum to one only if the backward shift, run from the offset path y = T(x)
towards the base pixel, makes the same decision at every vertex and so returns x. Reconnection is
symmetric: the criterion "x_b, x'_b and the next vertex connectable, the segments to it long enough
(``reconnection.far_enough``, in the mixed kernels) and the one from x'_b free" reads the same from
y, whose next vertex *is* x_{b+1}. Any other action leaves the offset at a vertex y_{b+1} of its own,
and the backward shift then asks the criterion about x_b, y_b and y_{b+1}: if it holds there, the
backward shift would reconnect x_b to y_{b+1} instead of returning x, so the forward shift must be
declared failed. The kernels run that check after every non-reconnecting step
(:func:`gdlearn.integrators.path.gpt_surface.mixed.inverse_reconnects`; Kettunen et al.'s policies use the stronger
rule "the next vertices agree in class", which implies it).

Mixed policies (:func:`is_mixed`): ``replay+reconnection`` -- the STAR's "simple but effective
approach to improve robustness" (Sec. 3.5) -- reconnects wherever the criterion holds and replays the
base's random numbers everywhere else, *including* where base and offset disagree in class: replay is
the identity in primary sample space, so it is reversible for any vertex kinds and needs no matching.
It fails only where the backward shift would reconnect (above). ``halfvector+replay+reconnection``
is the same with the half-vector copy where base and offset are both non-connectable (glossy below
the threshold, specular). Kettunen et al.'s ``halfvector+reconnection`` keeps its published rule:
fail on a class mismatch.

The integrators count what ran in a stats vector indexed by the ``STAT_*`` constants below
(:func:`record`), so every frame can report which shifts ran, succeeded and failed.
"""
import numpy as np


from gdlearn.kernels import layout as L
from gdlearn.shifts.reconnection import connectable
from gdlearn.kernels.jit import block, ir_inline, leaf, noalloc

# --- policies --------------------------------------------------------------------------------
POLICY_REPLAY = 0
POLICY_REPLAY_RECONNECTION = 1
POLICY_HALFVECTOR_RECONNECTION = 2
POLICY_HALFVECTOR_RECONNECTION_MANIFOLD = 3
POLICY_HALFVECTOR_REPLAY_RECONNECTION = 4

POLICIES = {"replay": POLICY_REPLAY,
            "replay+reconnection": POLICY_REPLAY_RECONNECTION,
            "halfvector+reconnection": POLICY_HALFVECTOR_RECONNECTION,
            "halfvector+reconnection+manifold": POLICY_HALFVECTOR_RECONNECTION_MANIFOLD,
            "halfvector+replay+reconnection": POLICY_HALFVECTOR_REPLAY_RECONNECTION}

# --- actions ---------------------------------------------------------------------------------
SHIFT_REPLAY = 0
SHIFT_HALFVECTOR = 1
SHIFT_RECONNECT = 2
SHIFT_MANIFOLD = 3
SHIFT_FAIL = 4
ACTION_NAMES = ("replay", "halfvector", "reconnection", "manifold", "fail")

#: longest specular chain the manifold walk is asked to move (chains of 1-3 vertices).
MAX_CHAIN = 3
#: class of a "vertex" at infinity (the path escaped): never connectable, must match on both paths
ESCAPED = -1

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


@block
def specular_chain_end(vclass, start, n):
    """Index of the first connectable vertex at or after ``start`` (n if none): the chain
    x_start .. x_{end-1} is the run of specular vertices the manifold walk would move."""
    i = start
    while i < n and vclass[i] == L.V_SPECULAR:
        i += 1
    return i


@ir_inline
def is_mixed(policy):
    """True for the policies that replay instead of failing on a class mismatch (module docstring)."""
    return policy == POLICY_REPLAY_RECONNECTION or policy == POLICY_HALFVECTOR_REPLAY_RECONNECTION


@block
def mixed_action(policy, conn_b, conn_o):
    """A mixed policy's action where no reconnection runs: the half-vector copy under
    ``halfvector+replay+reconnection`` when neither the base nor the offset vertex is connectable
    (both glossy below the threshold or specular, Sec. 3.2), random replay otherwise (Sec. 3.1).
    ``conn_b`` / ``conn_o``: is the base / offset vertex connectable. Symmetric in the two, so the
    backward shift, which swaps them, chooses the same action."""
    if policy == POLICY_HALFVECTOR_REPLAY_RECONNECTION and not conn_b and not conn_o:
        return SHIFT_HALFVECTOR
    return SHIFT_REPLAY


@leaf
def conn(c):
    """Is a vertex of class ``c`` connectable (:func:`gdlearn.shifts.reconnection.connectable`)? An
    escaped path (:data:`ESCAPED`) never is."""
    return c != ESCAPED and connectable(c)


@noalloc
def decide(policy, cls_b, cls_o, cls_next):
    """The table for Kettunen et al.'s policies with the next base vertex known (``cls_next``, or
    :data:`ESCAPED`): fail if base and offset disagree on connectability (not invertible, Kettunen
    et al. 2015), reconnect when x_b, x'_b and x_{b+1} are connectable, else replay or the
    half-vector copy. ``cls_b`` is the class of the lobe the base sampled (V_SPECULAR for a delta
    lobe). The renderer's kernels call this function; :func:`choose_shift` is its form over a whole
    vertex-class list (with the manifold choice and the next-event segment)."""
    cb = conn(cls_b)
    if cb != conn(cls_o):
        return SHIFT_FAIL
    if policy == POLICY_REPLAY:
        return SHIFT_REPLAY
    if cb and conn(cls_next):
        return SHIFT_RECONNECT
    if policy == POLICY_REPLAY_RECONNECTION:
        return SHIFT_REPLAY
    return SHIFT_HALFVECTOR


@leaf
def mixed_decide(policy, cls_b, cls_o, cls_next):
    """The table for the mixed policies (:func:`is_mixed`): reconnect where x_b, x'_b and x_{b+1} are
    all connectable, else :func:`mixed_action`. The kernels call it; where the reconnecting segment
    turns out blocked they continue with :func:`mixed_action` (and so would the backward shift)."""
    cb, co = conn(cls_b), conn(cls_o)
    if cb and co and conn(cls_next):
        return SHIFT_RECONNECT
    return mixed_action(policy, cb, co)


@block
def choose_shift(policy, class_b, class_b_offset, vclass_base, b, n):
    """The action for the segment leaving vertex b >= 1 (module docstring); the primary segment
    (sensor -> x_1) is shifted by the pixel offset itself, which the integrator does.

    ``vclass_base`` holds the base path's vertex classes (n valid vertices); ``class_b_offset`` is
    the class of the already shifted offset vertex x'_b; ``b + 1 == n`` is the segment to a light
    sample (next-event estimation). This is the decision table alone, made of the functions the
    kernels call (:func:`decide`, :func:`mixed_decide`); the kernels add the visibility of the
    reconnecting segment and the reversibility check of the step that did not reconnect.
    """
    if policy == POLICY_REPLAY:          # the identity in primary sample space: never a mismatch
        return SHIFT_REPLAY
    nxt = vclass_base[b + 1] if b + 1 < n else L.V_DIFFUSE
    if is_mixed(policy):
        # a light sample is connectable: next-event reconnects from a connectable pair
        return mixed_decide(policy, class_b, class_b_offset, nxt)
    if b + 1 >= n:
        # no next base vertex: the segment to a light sample is reconnected from a connectable vertex;
        # from a specular one it can only follow the copied direction
        return decide(policy, class_b, class_b_offset, L.V_DIFFUSE)
    if policy == POLICY_HALFVECTOR_RECONNECTION_MANIFOLD and conn(class_b) and conn(class_b_offset) \
            and nxt == L.V_SPECULAR:
        end = specular_chain_end(vclass_base, b + 1, n)
        if end < n and end - (b + 1) <= MAX_CHAIN:
            return SHIFT_MANIFOLD
    return decide(policy, class_b, class_b_offset, nxt)


@block
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
