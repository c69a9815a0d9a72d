"""Estimators. Every one follows the protocol of :mod:`gdlearn.integrators.base`.

``make(name, scene, **options)`` builds an integrator by its CLI name; the registry maps names to
classes lazily so importing gdlearn does not compile (or even import) every estimator.
"""
from __future__ import annotations

import importlib

from gdlearn.integrators.base import Frame, PassResult, ProgressiveIntegrator, render

#: CLI name -> "module:Class". Each estimator module adds its own line.
REGISTRY = {
    "pt": "gdlearn.integrators.path.pt:PathTracer",
    "gpt-replay": "gdlearn.integrators.path.gpt_replay:ReplayGPT",
    "gpt": "gdlearn.integrators.path.gpt:GradientPathTracer",
    "sppm": "gdlearn.integrators.photon.sppm:SPPM",
    "ppm": "gdlearn.integrators.photon.sppm:PPM",
    "gpm": "gdlearn.integrators.photon.gpm:GPM",
    "vpm": "gdlearn.integrators.photon.volumetric:VPM",
    "bre": "gdlearn.integrators.photon.volumetric:BRE",
    "gvpm": "gdlearn.integrators.photon.gvpm:GVPM",
    "gbre": "gdlearn.integrators.photon.gbre:GBRE",
    "lt": "gdlearn.integrators.photon.light_tracing:MediumLightTracer",
}


def get(name: str):
    """The integrator class registered under ``name`` (e.g. ``"pt"``)."""
    try:
        mod, cls = REGISTRY[name].split(":")
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; choose one of: {', '.join(sorted(REGISTRY))}") from None
    return getattr(importlib.import_module(mod), cls)


def make(name: str, scene, **options) -> ProgressiveIntegrator:
    """``make("pt", scene, seed=1, spp_per_pass=4, effects=["direct"])``."""
    return get(name)(scene, **options)


__all__ = ["Frame", "PassResult", "ProgressiveIntegrator", "render", "get", "make", "REGISTRY"]
