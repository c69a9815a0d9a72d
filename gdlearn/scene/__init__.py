"""Scene files to arrays: ``load`` (XML subset -> :class:`Scene`), ``effects`` (the effects plan),
and :func:`gdlearn.scene.compile.compile_scene` (flat numba-ready arrays). See ARCHITECTURE.md, "The road a scene travels".

``gdlearn.scene.effects`` is the effects module; calling it, ``effects(scene, request)``, is
``effects.plan(scene, request)``.
"""
from gdlearn.scene import effects  # noqa: F401  (callable module: effects(scene, request) -> EffectsPlan)
from gdlearn.scene.effects import EffectsPlan, plan  # noqa: F401
from gdlearn.scene.load import load  # noqa: F401
from gdlearn.scene.model import Scene, SceneError  # noqa: F401

