"""Exercise "offset-photon" (chapter: Gradient-domain photon mapping). Fill in the two functions.

Run ``gdlearn check offset-photon`` to test them (see README.md).
"""


def offset_target(y, z, frame, z_o, frame_o):
    """Eq. 5 of Hua et al. 2017: y* = z' + M' M^-1 (y - z), with frame = (n, s, t) at z and
    frame_o = (n', s', t') at z' (orthonormal world vectors). Returns a 3-tuple."""
    raise NotImplementedError("offset_target is not written yet (see README.md)")


def projection_jacobian(y_parent, y_star, n_star, y_hit, n_hit):
    """Eq. 6 of Hua et al. 2017: |dy'/dy*| = (|cos*| / d*^2) / (|cos'| / d'^2) for the projection of
    y* (normal n_star) onto y' (normal n_hit) along the ray from y_parent; 0.0 when degenerate."""
    raise NotImplementedError("projection_jacobian is not written yet (see README.md)")
