"""Turn a frame into the final image: the primal estimate, or a gradient-domain reconstruction.

The experiments module never reconstructs by itself; it calls :mod:`gdlearn.reconstruct` by the
solver names the CLI uses (``--solver``):

* ``cv``          -- iterative control-variate reconstruction (STAR, Hua et al. 2019, §2.3, Algorithm 1);
* ``cv-weighted`` -- weighted control variates (Hua et al. 2019, §5, Eq. 20-22), weights from the frame's
  two independent half-buffers (``halves=``: the solver pools their variance estimates over 3 x 3
  pixels, :mod:`gdlearn.reconstruct.control_variates`);
* ``l2`` / ``l1`` -- screened Poisson reconstruction, L2 or L1 norm (Hua et al. 2019, §5, Eq. 18-19), with
  the papers' alpha = 0.2 (Hua et al. 2017 §5: "the lambda parameter for Poisson reconstruction is set to
  a small value, lambda = 0.2").

A frame that carries ``emission`` with its gradients ``emission_gx``, ``emission_gy`` (gpm: the
emission its camera paths see directly or through specular chains, which every sample evaluates
exactly) is reconstructed without that part, which is added back afterwards: a light's edge makes
gradients of the light's radiance from only a few camera samples a pixel, and a screened Poisson
solve would smear their noise over the dim surfaces around it.

A solver may also be any callable ``f(frame) -> image``; tests use that to stay independent of the
reconstruction library.
"""
from __future__ import annotations

import importlib
import inspect

import numpy as np

#: the solver names of the CLI's ``--solver`` and of :class:`~gdlearn.experiments.study.Method` specs
SOLVER_NAMES = ("cv", "cv-weighted", "l2", "l1")
#: solver name -> (function name in gdlearn.reconstruct, whether it wants variances as weights)
_FUNCTIONS = {
    "cv": ("control_variates", False),
    "cv-weighted": ("control_variates", True),
    "l2": ("poisson_l2", False),
    "l1": ("poisson_l1", False),
}


def resolve(solver):
    """A callable ``frame -> image`` for ``solver`` (a name from :data:`SOLVER_NAMES`, a callable,
    or None for "use the primal image")."""
    if solver is None or callable(solver):
        return solver
    if solver not in _FUNCTIONS:
        raise ValueError(f"unknown solver {solver!r}; choose one of: {', '.join(SOLVER_NAMES)}")
    fname, weighted = _FUNCTIONS[solver]
    try:
        fn = getattr(importlib.import_module("gdlearn.reconstruct"), fname)
    except (ImportError, AttributeError) as err:
        raise RuntimeError(f"solver {solver!r} needs gdlearn.reconstruct.{fname}, which is not "
                           f"available ({err}); use --solver with an available one or a callable") from err
    return _Bound(solver, fn, weighted)


class _Bound:
    """A picklable ``frame -> image`` wrapper around one gdlearn.reconstruct function."""

    def __init__(self, name, fn, weighted):
        self.name, self.fn, self.weighted = name, fn, weighted

    def __call__(self, frame, **options):
        if frame.gx is None or frame.gy is None:
            raise ValueError(f"solver {self.name!r} needs gradient images (gx, gy), but the "
                             "integrator produced only a primal image; drop --solver for primal methods")
        kwargs = dict(options)
        params = inspect.signature(self.fn).parameters
        primal, gx, gy, halves = frame.primal, frame.gx, frame.gy, frame.halves
        kept = frame.images.get("emission") if "emission_gx" in frame.images else None
        if kept is not None:
            # the estimator split off a part it estimates well by itself (the emission its camera
            # paths see, sampled exactly): the solver reconstructs the rest, the part is added back
            part = {"primal": "emission", "gx": "emission_gx", "gy": "emission_gy"}
            primal, gx, gy = (frame.images[n] - frame.images[part[n]] for n in ("primal", "gx", "gy"))
            halves = {n: (halves[n][0] - halves[e][0], halves[n][1] - halves[e][1]) for n, e in part.items()}
        if self.weighted and "halves" in params:
            # the solver estimates (and pools) the variances from the two half-buffers itself
            kwargs.setdefault("halves", {n: halves[n] for n in ("primal", "gx", "gy")})
        elif self.weighted:
            # Weighted reconstructions take per-pixel variances of primal and gradients (Eq. 20-22).
            var = {n: 0.25 * (halves[n][0] - halves[n][1]) ** 2 for n in ("primal", "gx", "gy")}   # Frame.variance
            if "weights" in params:
                kwargs.setdefault("weights", var)
            elif "variances" in params:
                kwargs.setdefault("variances", var)
            else:
                for n in ("primal", "gx", "gy"):
                    if f"var_{n}" in params:
                        kwargs.setdefault(f"var_{n}", var[n])
            if "weighted" in params:
                kwargs.setdefault("weighted", True)
        out = self.fn(primal, gx, gy, **kwargs)
        if hasattr(out, "image"):           # gdlearn.reconstruct.Reconstruction
            out = out.image
        elif isinstance(out, tuple):        # (image, info) style results
            out = out[0]
        out = np.asarray(out, dtype=np.float64)
        return out if kept is None else out + kept

    def __reduce__(self):                   # pickle by name: workers re-import gdlearn.reconstruct
        return (resolve, (self.name,))


def final_image(frame, solver=None, **options) -> np.ndarray:
    """The frame's final estimate: ``solver(frame)`` if a solver is given, else the primal image."""
    fn = resolve(solver)
    return frame.primal if fn is None else fn(frame, **options)
