"""Exercise "cosine-hemisphere" (chapter: Rendering as integration). Fill in the three functions.

Run ``gdlearn check cosine-hemisphere`` to test them. Directions are 3-tuples of floats (x, y, z)
in the local frame whose +z axis is the surface normal, so cos(theta) = z.
"""
import math

import numpy as np


def square_to_cosine_hemisphere(u1: float, u2: float) -> tuple[float, float, float]:
    """A direction on the +z hemisphere with density cos(theta) / pi, from (u1, u2) in [0, 1)^2."""
    raise NotImplementedError("square_to_cosine_hemisphere is not written yet (see README.md)")


def cosine_hemisphere_pdf(w: tuple[float, float, float]) -> float:
    """The solid-angle density of square_to_cosine_hemisphere at direction w (0 below the horizon)."""
    raise NotImplementedError("cosine_hemisphere_pdf is not written yet (see README.md)")


def irradiance_estimate(sky, n: int, seed: int) -> float:
    """Monte Carlo estimate of E = int sky(w) cos(theta) dw over the hemisphere, with n
    cosine-weighted samples from numpy.random.default_rng(seed). ``sky(w)`` returns a float."""
    raise NotImplementedError("irradiance_estimate is not written yet (see README.md)")
