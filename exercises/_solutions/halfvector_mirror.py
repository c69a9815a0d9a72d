"""Solution of the exercise "halfvector-mirror" (exercises/halfvector-mirror/README.md).

gdlearn implements this piece: :func:`gdlearn.shifts.halfvector.halfvector_copy` with eta = 1 and no
transmission is the reflection case of Eq. 15 -- h = normalize(wi_b + wo_b), wo_o = 2 (wi_o . h) h - wi_o,
and J = |dh/dwo|(base) / |dh/dwo|(offset) = |wo_o . h| / |wo_b . h| (Walter et al. 2007, Eq. 14;
Kettunen et al. 2015) -- with the same failure flags. The solution only converts the arguments.
"""
from gdlearn.shifts.halfvector import halfvector_copy


def _t(v):
    return (float(v[0]), float(v[1]), float(v[2]))


def halfvector_copy_mirror(wi_b, wo_b, wi_o):
    wo_o, j, ok = halfvector_copy(_t(wi_b), _t(wo_b), _t(wi_o), 1.0, False)
    return tuple(float(c) for c in wo_o), float(j), bool(ok)


__all__ = ["halfvector_copy_mirror"]
