"""Exercise "replay" (chapter: The first gradient-domain renderer). Fill in the two functions.

Run ``gdlearn check replay`` to test them. ``radiance(u, fx, fy)`` returns a float: the contribution
of the path made from the uniform numbers ``u`` (a numpy array) through the film point (fx, fy);
pixel (x, y) covers [x, x + 1) x [y, y + 1). Images are ``height x width`` numpy arrays, indexed
``[y, x]``.
"""
import numpy as np


def accumulate(radiance, width: int, height: int, spp: int, seed: int, dims: int = 4):
    """Algorithm 1's sampling loop: returns (P, Gx, Gy), see README.md."""
    raise NotImplementedError("accumulate is not written yet (see README.md)")


def reconstruct(P, Gx, Gy, iterations: int = 50):
    """Algorithm 1's reconstruct (Eq. 14): returns the image I, see README.md."""
    raise NotImplementedError("reconstruct is not written yet (see README.md)")
