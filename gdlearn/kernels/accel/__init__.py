"""Acceleration structures: the BVH, its builder, SIMD leaf blocks and packet traversal."""
