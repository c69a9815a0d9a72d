"""Exercise "sppm-update" (chapter: Photon density estimation). Fill in the two functions.

Run ``gdlearn check sppm-update`` to test them (see README.md).
"""


def progressive_update(N, r2, tau, M, phi, alpha):
    """One SPPM pass for one pixel: (N + alpha M, R^2 (N + alpha M) / (N + M), (tau + Phi) R'^2 / R^2);
    nothing changes when N + M = 0."""
    raise NotImplementedError("progressive_update is not written yet (see README.md)")


def radiance(tau, r2, n_emitted):
    """The pixel value tau / (pi R^2 n_emitted)."""
    raise NotImplementedError("radiance is not written yet (see README.md)")
