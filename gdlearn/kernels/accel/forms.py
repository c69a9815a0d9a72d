"""The BVH's *form*, one leaf or a tree, in the type numba compiles the traversals for.

Nine of the ten shipped scenes are small enough for one leaf (:mod:`gdlearn.kernels.accel.bvh_build`:
the surface-area heuristic keeps a few dozen lanes together), and their rays never enter a wide
node. Compiling the tree traversal anyway (the wide nodes' slab tests and sort, the stack, and the
packet tracer's ray-by-ray fallback for trees) was a fifth of ``pt``'s cold compile on the Cornell
box and a quarter on the volume caustic (benchmarks/README.md, "One leaf, compiled as one leaf").

numba types an array's write flag, so :func:`gdlearn.kernels.accel.bvh_build.build_scene` hands out
the ``node_info`` table of a one-leaf BVH read-only, and the traversals (``bvh.closest_hit_inline``,
``bvh.any_hit_inline``, ``packet._trace``) are ``overload``\\ s that pick, by that flag, the
leaf's code alone or the code for any tree. A writable table (a user's, or a copy) gets the code
for any tree, which tests for one leaf at run time: the flag only decides what is compiled, never
what a ray hits. The materials table's flags name its BSDF tier the same way
(:mod:`gdlearn.kernels.bsdf.tiers`).
"""
import numpy as np


def mark_form(node_info: np.ndarray) -> np.ndarray:
    """``node_info`` in the form of its BVH: read-only when the root is a leaf (its count > 0)."""
    node_info.flags.writeable = not node_info[0, 1] > 0
    return node_info


def one_leaf(node_info_type) -> bool:
    """At typing: is ``node_info_type`` (a numba array type) the table of a one-leaf BVH?"""
    return not getattr(node_info_type, "mutable", True)
