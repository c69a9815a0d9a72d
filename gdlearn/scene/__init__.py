"""Scene files to arrays: ``load`` (XML subset -> :class:`Scene`), ``effects`` (the effects plan),
``compile`` (flat numba-ready arrays). See ARCHITECTURE.md, "The road a scene travels".

``gdlearn.scene.effects`` is the effects module; calling it, ``effects(scene, request)``, is
``effects.plan(scene, request)``.
"""
from . import effects  # noqa: F401  (callable module: effects(scene, request) -> EffectsPlan)
from .effects import EffectsPlan, plan  # noqa: F401
from .load import load  # noqa: F401
from .model import Scene, SceneError  # noqa: F401


def compile(scene, plan=None):  # noqa: A001  (the arrow "scene.compile" of ARCHITECTURE.md)
    """``compile_scene(scene, plan)``: the flat numba-ready arrays (imported lazily: it pulls in numba)."""
    from .compile import compile_scene
    return compile_scene(scene, plan)
