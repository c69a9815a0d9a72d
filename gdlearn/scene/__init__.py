"""Scene files to arrays: ``load`` (XML subset -> :class:`Scene`), ``effects`` (the effects plan),
``compile`` (flat numba-ready arrays). See ARCHITECTURE.md, "The road a scene travels"."""
from .model import Scene, SceneError  # noqa: F401


def __getattr__(name):
    # Lazy so that `import gdlearn.scene` stays cheap (compile pulls in numba).
    if name == "load":
        from .load import load
        return load
    if name in ("effects", "EffectsPlan"):
        from . import effects as _e
        return getattr(_e, "plan" if name == "effects" else name)
    if name == "compile":
        from .compile import compile_scene
        return compile_scene
    raise AttributeError(name)
