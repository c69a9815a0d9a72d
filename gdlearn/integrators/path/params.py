"""The per-render constants of the gradient kernels, bundled: :class:`GptParams`.

numba passes a NamedTuple as a struct (one argument, no per-field cost once LLVM has inlined the
callee), so the kernels take ``cfg`` instead of six loose scalars, and a reader sees at a glance
which arguments are per-render constants and which change per vertex. Kettunen and Manzi's
gradient-domain Mitsuba bundles the same options (``GradientPathTracerConfig``).
"""
from __future__ import annotations

from typing import NamedTuple


class GptParams(NamedTuple):
    """``policy``: the shift policy code (:mod:`gdlearn.shifts.policy`); ``max_depth`` (a loop bound),
    ``rr_depth``, ``mask`` (the effects mask) and ``threshold`` (roughness below which a vertex counts
    as specular) as :class:`gdlearn.integrators.setup.SceneSetup`; ``broken``: the fault injected for
    the tests that must be able to fail (``gpt_surface.vertex.BROKEN_*``; 0 is the estimator)."""
    policy: int
    max_depth: int
    rr_depth: int
    mask: int
    threshold: float
    broken: int

    @classmethod
    def of(cls, setup, policy: int, broken: int = 0) -> "GptParams":
        """The bundle for a :class:`~gdlearn.integrators.setup.SceneSetup` (types fixed, so every render
        reuses one compiled specialisation)."""
        return cls(int(policy), int(setup.max_depth), int(setup.rr_depth), int(setup.mask), float(setup.threshold),
                   int(broken))
