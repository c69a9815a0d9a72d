"""One shift decision table: the one the renderer runs, the book draws and the tests check.

1. ``shifts.policy.choose_shift`` (the table over a vertex-class list, which the book's figures
   call) agrees with an independent transcription of the rules -- Kettunen et al. 2015's policy
   (fail on a class mismatch, reconnect when x_b, x'_b and x_{b+1} are connectable, manifold
   exploration of a short specular chain, else the half-vector copy) and the mixed policies of the
   STAR (Hua et al. 2019, Sec. 3.5: replay where no reconnection runs, the half-vector copy between
   two non-connectable vertices) -- on random vertex-class sequences, for every policy and vertex.
2. The renderer's kernels make their per-segment decisions with the same functions
   (``decide``, ``mixed_decide``), not with copies: no module under ``gdlearn/integrators`` defines
   a decision function of its own.
"""
import ast
from pathlib import Path

import numpy as np
import pytest

from gdlearn.kernels import layout as L
from gdlearn.shifts import policy as P

D, G, S, M = L.V_DIFFUSE, L.V_GLOSSY, L.V_SPECULAR, L.V_MEDIUM
ROOT = Path(__file__).resolve().parent.parent


def _connectable(c):
    return c in (D, G, M)


def oracle(policy, cb_cls, co_cls, classes, b):
    """The rules as the papers state them, written without the library's helpers."""
    n = len(classes)
    has_next = b + 1 < n
    nxt = classes[b + 1] if has_next else D          # a light sample: a connectable end point
    cb, co = _connectable(cb_cls), _connectable(co_cls)
    if policy == P.POLICY_REPLAY:
        return P.SHIFT_REPLAY
    if policy in (P.POLICY_REPLAY_RECONNECTION, P.POLICY_HALFVECTOR_REPLAY_RECONNECTION):
        if cb and co and _connectable(nxt):
            return P.SHIFT_RECONNECT
        if policy == P.POLICY_HALFVECTOR_REPLAY_RECONNECTION and not cb and not co:
            return P.SHIFT_HALFVECTOR
        return P.SHIFT_REPLAY
    if cb != co:
        return P.SHIFT_FAIL
    if cb and _connectable(nxt):
        return P.SHIFT_RECONNECT
    if policy == P.POLICY_HALFVECTOR_RECONNECTION_MANIFOLD and cb and has_next and nxt == S:
        end = b + 1
        while end < n and classes[end] == S:
            end += 1
        if end < n and end - (b + 1) <= P.MAX_CHAIN:
            return P.SHIFT_MANIFOLD
    return P.SHIFT_HALFVECTOR


@pytest.mark.parametrize("policy", sorted(P.POLICIES.values()))
def test_the_table_follows_the_papers_rules_on_random_class_sequences(policy):
    rng = np.random.default_rng(17 + policy)
    seen = set()
    for _ in range(3000):
        n = int(rng.integers(2, 9))
        # specular runs more often than uniform draws would give, so chains of 1..MAX_CHAIN+1 occur
        classes = rng.choice([D, G, S, S, M], size=n).astype(np.int32)
        classes[0] = D                                  # the sensor counts as connectable
        b = int(rng.integers(1, n))
        off = int(rng.choice([D, G, S, M]))
        got = P.choose_shift(policy, classes[b], off, classes, b, n)
        assert got == oracle(policy, int(classes[b]), off, list(classes), b), (policy, list(classes), b, off)
        seen.add(got)
    # the sample reaches every action the policy can take
    expect = {P.POLICY_REPLAY: {P.SHIFT_REPLAY},
              P.POLICY_REPLAY_RECONNECTION: {P.SHIFT_REPLAY, P.SHIFT_RECONNECT},
              P.POLICY_HALFVECTOR_REPLAY_RECONNECTION: {P.SHIFT_REPLAY, P.SHIFT_RECONNECT, P.SHIFT_HALFVECTOR},
              P.POLICY_HALFVECTOR_RECONNECTION: {P.SHIFT_FAIL, P.SHIFT_RECONNECT, P.SHIFT_HALFVECTOR},
              P.POLICY_HALFVECTOR_RECONNECTION_MANIFOLD: {P.SHIFT_FAIL, P.SHIFT_RECONNECT, P.SHIFT_HALFVECTOR,
                                                          P.SHIFT_MANIFOLD}}[policy]
    assert seen == expect


def test_the_next_vertex_forms_are_the_table_the_kernels_call():
    """decide / mixed_decide (next class known) give the table's action; an escaped next vertex is
    never connectable, like an open specular chain (which no manifold walk can close)."""
    for policy in P.POLICIES.values():
        if policy == P.POLICY_REPLAY:       # whole-path replay never asks (its own kernel)
            continue
        f = P.mixed_decide if P.is_mixed(policy) else P.decide
        for cb in (D, G, S, M):
            for co in (D, G, S, M):
                for nxt in (D, G, M, P.ESCAPED):
                    tail = [D, cb, nxt] if nxt != P.ESCAPED else [D, cb, S]
                    assert f(policy, cb, co, nxt) == oracle(policy, cb, co, tail, 1), (policy, cb, co, nxt)


DECISIONS = {"decide", "mixed_decide", "mixed_action", "choose_shift"}


def test_no_estimator_module_keeps_a_decision_table_of_its_own():
    for path in sorted((ROOT / "gdlearn" / "integrators").rglob("*.py")):
        tree = ast.parse(path.read_text())
        own = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)} & DECISIONS
        assert not own, f"{path.relative_to(ROOT)} defines {own}: the table lives in gdlearn/shifts/policy.py"
    from gdlearn.integrators.path.gpt_surface import lockstep as surf, mixed as smix
    from gdlearn.integrators.path.gpt_volume import lockstep as vol, mixed as vmix
    assert surf.decide is P.decide and vol.decide is P.decide
    assert smix.mixed_decide is P.mixed_decide and vmix.mixed_decide is P.mixed_decide
