"""Equal-time (and equal-sample) studies: methods x scenes x seeds -> a tidy table of records.

Each (method, scene, seed) is one :class:`Task`: build the integrator, run it progressively
(:func:`gdlearn.experiments.progressive.run`) under the same budget as every other method, measure
every snapshot against the scene's reference. A task returns one *record* (a flat dict) per
snapshot -- the tidy layout in which the convergence plots, "time to reach relMSE x" and equal-time
ratios are simple group-bys (:mod:`.plots`), and which :meth:`Study.to_csv` writes as is.

The comparison is the papers' (Hua et al. 2019 §4.5 "a comprehensive equal-time comparison"; Gruson et al. 2018 §6):
every method gets the same wall-clock budget, JIT compile excluded, reconstruction included.
"""
from __future__ import annotations

import csv
import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gdlearn.experiments import metrics, progressive
from gdlearn.experiments.executors import get_executor


@dataclass(frozen=True)
class Method:
    """A method of a study: an estimator (registry name such as ``"gpt"``, ``"module:Class"`` or a
    class) with an optional solver for its gradients and integrator options."""
    label: str
    estimator: Any
    solver: Any = None
    options: tuple = ()                  # (key, value) pairs, hashable

    @classmethod
    def parse(cls, spec, solver=None) -> "Method":
        """``"pt"``, ``"gpt+l1"`` (estimator + solver), ``"bre:kernel=2d:radii=variable"``
        (integrator options as ``:key=value``; numbers are read as numbers) or a Method; ``solver``
        is the default solver for specs that name none (it applies only to estimators that produce
        gradients)."""
        if isinstance(spec, Method):
            return spec
        if isinstance(spec, str):
            est, _, sol = spec.partition("+")
            parts = est.split(":")
            name = ":".join(p for p in parts if "=" not in p)
            options = tuple(_option(p) for p in parts if "=" in p)
            return cls(spec if sol else (f"{est}+{solver}" if solver else est), name, sol or solver, options)
        return cls(getattr(spec, "name", str(spec)), spec, solver)


def _option(item: str) -> tuple:
    """``"key=value"`` -> (key, value), the value as an int or float where it reads as one."""
    key, _, value = item.partition("=")
    for kind in (int, float):
        try:
            return key, kind(value)
        except ValueError:
            pass
    return key, value


@dataclass
class Task:
    """Everything one worker needs; picklable (scenes travel as paths or small objects)."""
    method: Method
    scene: Any
    seed: int
    seconds: float | None = None
    passes: int | None = None
    count: int = 12
    spp_per_pass: int = 1
    reference: np.ndarray | None = None
    reference_floor: float | None = None
    keep_images: str = "final"
    first: float | None = None           # first snapshot time (time budgets; default seconds/100)


@dataclass(frozen=True)
class SceneFile:
    """A scene file with overrides of its ``<default>`` parameters, e.g.
    ``SceneFile("scenes/cornell-box.xml", (("res", 32),))`` -- what ``gdlearn.scene.load(path,
    res=32)`` and ``mitsuba.load_file(path, res=32)`` receive. Picklable, hashable."""
    path: str
    defaults: tuple = ()

    @property
    def name(self) -> str:
        return Path(self.path).stem

    def load(self):
        return _scene_loader()(str(self.path), **dict(self.defaults))


def _scene_loader():
    # The function, not the package attribute: importing the submodule gdlearn.scene.load rebinds
    # gdlearn.scene.load to the module.
    return importlib.import_module("gdlearn.scene.load").load


def scene_name(scene) -> str:
    """A short name for records: a file's stem, or the object's ``name``."""
    if isinstance(scene, (str, Path)):
        return Path(scene).stem
    if scene is None:
        return "none"
    return str(getattr(scene, "name", None) or type(scene).__name__)


def load_scene(scene):
    """A scene file path (or :class:`SceneFile`) is loaded with :func:`gdlearn.scene.load`; other
    objects (e.g. a toy scene) pass through."""
    if isinstance(scene, (str, Path)):
        return _scene_loader()(str(scene))
    if isinstance(scene, SceneFile):
        return scene.load()
    return scene


def make_integrator(estimator, scene, seed: int, spp_per_pass: int = 1, **options):
    """Build an integrator from a registry name, a ``"module:Class"`` string or a class."""
    if isinstance(estimator, str) and ":" in estimator:
        mod, cls = estimator.split(":")
        estimator = getattr(importlib.import_module(mod), cls)
    if isinstance(estimator, str):
        from gdlearn.integrators import make
        return make(estimator, scene, seed=seed, spp_per_pass=spp_per_pass, **options)
    return estimator(scene, seed=seed, spp_per_pass=spp_per_pass, **options)


def run_task(task: Task) -> dict:
    """Run one task; returns ``{"records": [...], "image": final image, "primal": ...}``."""
    scene = load_scene(task.scene)
    m = task.method
    integ = make_integrator(m.estimator, scene, task.seed, task.spp_per_pass, **dict(m.options))
    run = progressive.run(integ, seconds=task.seconds, passes=task.passes, count=task.count,
                          first=task.first,
                          solver=m.solver,
                          reference=task.reference, reference_floor=task.reference_floor,
                          keep_images=task.keep_images)
    base = {"method": m.label, "estimator": getattr(integ, "name", str(m.estimator)),
            "scene": scene_name(task.scene), "seed": task.seed,
            "compile_seconds": run.compile_seconds, "interrupted": run.interrupted}
    records = []
    for i, s in enumerate(run.snapshots):
        rec = dict(base, snapshot=i, final=(i == len(run.snapshots) - 1), passes=s.passes,
                   spp=s.spp, seconds=s.seconds, render_seconds=s.render_seconds,
                   reconstruct_seconds=s.reconstruct_seconds,
                   solver=(_solver_name(m.solver) if "reconstruct" in s.timings else None))
        rec.update(s.errors)
        rec.update({f"t_{k}": v for k, v in s.timings.items()})
        rec.update({f"n_{k}": v for k, v in s.stats.items()})
        records.append(rec)
    images = [s.image for s in run.snapshots] if task.keep_images == "all" else None
    return {"records": records, "image": run.final.image, "primal": run.final.primal,
            "images": images}


def _solver_name(solver) -> str:
    return solver if isinstance(solver, str) else getattr(solver, "__name__", type(solver).__name__)


@dataclass
class Study:
    """The outcome of :func:`equal_time`: tidy records, final images, references."""
    records: list[dict]
    images: dict[tuple, np.ndarray] = field(default_factory=dict)     # (method, scene, seed) -> image
    references: dict[str, Any] = field(default_factory=dict)          # scene name -> Reference/array
    snapshots: dict[tuple, list] = field(default_factory=dict)        # with keep_images="all"

    def select(self, final: bool | None = None, **where) -> list[dict]:
        """Records matching every ``column=value`` (and ``final``, if given)."""
        out = [r for r in self.records if all(r.get(k) == v for k, v in where.items())]
        return out if final is None else [r for r in out if r["final"] == final]

    def methods(self) -> list[str]:
        return list(dict.fromkeys(r["method"] for r in self.records))

    def seed_images(self, method: str, scene: str) -> list[np.ndarray]:
        """The final images of ``method`` on ``scene``, one per seed in seed order (what
        :func:`gdlearn.experiments.metrics.bias_variance` splits)."""
        return [img for (m, s, _), img in sorted(self.images.items(), key=lambda kv: kv[0][2])
                if m == method and s == scene]

    def scenes(self) -> list[str]:
        return list(dict.fromkeys(r["scene"] for r in self.records))

    def to_csv(self, path) -> Path:
        """Write the records (one row per snapshot; the union of all columns) to ``path``."""
        cols = list(dict.fromkeys(k for r in self.records for k in r))
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=cols, restval="")
            w.writeheader()
            w.writerows(self.records)
        return path

    def merge(self, other: "Study") -> "Study":
        """This study and ``other`` as one (records, images, references, snapshots), e.g. a method
        run on one scene only beside the methods run on all: ratios then compare it with the
        baseline of its scene. ``other`` wins where both have an image under the same key."""
        return Study(self.records + other.records, {**self.images, **other.images},
                     {**self.references, **other.references}, {**self.snapshots, **other.snapshots})

    def time_to_reach(self, target: float, metric: str = "relmse") -> dict[tuple, float]:
        """(method, scene, seed) -> first time its ``metric`` curve reaches ``target`` (NaN if never)."""
        out = {}
        for key in dict.fromkeys((r["method"], r["scene"], r["seed"]) for r in self.records):
            rs = self.select(method=key[0], scene=key[1], seed=key[2])
            out[key] = metrics.time_to_reach([r["seconds"] for r in rs],
                                             [r.get(metric, np.nan) for r in rs], target)
        return out

    def equal_time_ratios(self, baseline: str, metric: str = "relmse",
                          less_floor: bool = False) -> dict[tuple, float]:
        """(method, scene) -> mean final ``metric`` of ``baseline`` / that of the method: how many
        times lower its error is at the same budget (> 1 means better than the baseline).

        ``less_floor`` subtracts the reference's noise floor (the records' ``relmse_floor``,
        :func:`gdlearn.experiments.metrics.relmse_floor`) from both mean relMSEs first. Measured
        against a noisy reference every error is the method's own plus the floor, which pulls every
        ratio towards 1; the difference is the methods' own errors (unbiased, since the reference is
        independent of the runs). NaN where an error does not rise above the floor.
        """
        if less_floor and metric != "relmse":
            raise ValueError(f"less_floor needs metric='relmse' (the floor is a relMSE), not {metric!r}")
        out = {}
        for scene in self.scenes():
            b = self._mean_final(baseline, scene, metric, less_floor)
            for m in self.methods():
                if not self.select(True, method=m, scene=scene):
                    continue                    # a method that did not run on this scene
                e = self._mean_final(m, scene, metric, less_floor)
                out[(m, scene)] = float(b / e) if e > 0 and b > 0 else float("nan")
        return out

    def seed_ratios(self, baseline: str, method: str, scene: str, metric: str = "relmse") -> np.ndarray:
        """Final ``metric`` of ``baseline`` / that of ``method`` on ``scene``, one ratio per seed both
        ran, in seed order: the spread of :meth:`equal_time_ratios`. The ratios are paired by seed
        because methods that share a seed share their base samples (gpt's base paths are pt's), so
        the per-seed ratio varies far less than either error does."""
        def finals(m):
            return {r["seed"]: r[metric] for r in self.select(True, method=m, scene=scene)}
        b, e = finals(baseline), finals(method)
        if not b or not e:
            raise KeyError(f"no final records of {baseline!r} and {method!r} on {scene!r}; "
                           f"methods {self.methods()}, scenes {self.scenes()}")
        return np.array([b[sd] / e[sd] for sd in sorted(set(b) & set(e))])

    def _mean_final(self, method, scene, metric, less_floor):
        recs = self.select(True, method=method, scene=scene)
        e = float(np.mean([r[metric] for r in recs]))
        if less_floor:
            e -= float(np.mean([r.get("relmse_floor", np.nan) for r in recs]))
        return e if np.isfinite(e) else float("nan")


def _reference_arrays(ref):
    if ref is None:
        return None, None
    if isinstance(ref, np.ndarray):
        return ref, None
    floor = getattr(ref, "floor", None)
    return ref.image, (None if floor is None or not np.isfinite(floor) else floor)


def equal_time(methods, scenes, *, seconds: float | None = None, passes: int | None = None,
               seeds=1, solver=None, references=None, executor=None, count: int = 12,
               spp_per_pass: int = 1, keep_images: str = "final", first: float | None = None) -> Study:
    """Run every method on every scene for every seed under one budget; return a :class:`Study`.

    ``methods``: specs for :meth:`Method.parse` (``"pt"``, ``"gpt+l1"``, classes, Methods).
    ``seeds``: a count (seeds 0..N-1) or a list. ``references``: scene name -> reference (array or
    :class:`~gdlearn.experiments.references.Reference`), or one reference for a single scene.
    ``executor``: anything :func:`!gdlearn.experiments.executors.get_executor` accepts, default a
    one-worker local process pool. ``count`` and ``first``: snapshots per run and the time of the
    first one (:func:`~gdlearn.experiments.progressive.time_schedule`).
    """
    methods = [Method.parse(m, solver) for m in methods]
    scenes = list(scenes) if isinstance(scenes, (list, tuple)) else [scenes]
    seeds = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
    if references is not None and not isinstance(references, dict):
        references = {scene_name(scenes[0]): references}
    references = references or {}
    tasks = []
    for sc in scenes:
        img, floor = _reference_arrays(references.get(scene_name(sc)))
        for m in methods:
            for sd in seeds:
                tasks.append(Task(m, sc, int(sd), seconds, passes, count, spp_per_pass, img, floor,
                                  keep_images, first))
    ex = get_executor(executor)
    try:
        results = ex.map(run_task, tasks)
    finally:
        if ex is not executor:           # close only what we created here
            ex.close()
    study = Study([], references=references)
    for t, res in zip(tasks, results):
        study.records.extend(res["records"])
        key = (t.method.label, scene_name(t.scene), t.seed)
        study.images[key] = res["image"]
        if res["images"] is not None:
            study.snapshots[key] = res["images"]
    return study
