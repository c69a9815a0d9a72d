"""Exercise "halfvector-mirror" (chapter: Shift mappings). Fill in the function.

Run ``gdlearn check halfvector-mirror`` to test it. Directions are unit 3-tuples (x, y, z) in the
vertex's local shading frame (normal = +z), pointing away from the vertex.
"""
import math

import numpy as np


def halfvector_copy_mirror(wi_b, wo_b, wi_o):
    """The half-vector copy (Eq. 15) at a reflecting vertex: returns (wo_o, jacobian, ok), see README.md."""
    raise NotImplementedError("halfvector_copy_mirror is not written yet (see README.md)")
