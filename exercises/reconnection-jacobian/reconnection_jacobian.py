"""Exercise "reconnection-jacobian" (chapter: Shift mappings). Fill in the function.

Run ``gdlearn check reconnection-jacobian`` to test it. Points and normals are 3-tuples (or numpy
arrays) of floats; a zero normal ``(0, 0, 0)`` marks a vertex inside a medium.
"""
import math

import numpy as np


def reconnection_jacobian(x_b, x_b_offset, y, n_y) -> float:
    """|dw'/dw| of the reconnection x_b -> y  ==>  x'_b -> y in the solid-angle measure at x_b
    (see README.md). Degenerate configurations return 0.0."""
    raise NotImplementedError("reconnection_jacobian is not written yet (see README.md)")
