"""Lambertian reflection (Mitsuba 3 plugin ``diffuse``): f = R / pi on the front side.

Sampling is cosine-weighted (Malley's method), so the sample weight f |cos wo| / pdf is exactly R.
One-sided like Mitsuba: a query with wi.z <= 0 or wo.z <= 0 gives 0 (``twosided`` is handled by the
dispatcher in :mod:`gdlearn.kernels.bsdf.dispatch`).
"""


from gdlearn.kernels.layout import MAT_R
from gdlearn.kernels.sampling import INV_PI, square_to_cosine_hemisphere
from gdlearn.kernels.jit import inlined

ZERO3 = (0.0, 0.0, 0.0)


@inlined
def diffuse_sample(mat, wi, u1, u2):
    """(wo, weight, pdf, is_delta) with wo ~ cos(theta) / pi and weight = R."""
    if wi[2] <= 0.0:
        return ZERO3, ZERO3, 0.0, False
    wo = square_to_cosine_hemisphere(u1, u2)
    pdf = wo[2] * INV_PI
    if pdf <= 0.0:
        return ZERO3, ZERO3, 0.0, False
    return wo, (mat[MAT_R], mat[MAT_R + 1], mat[MAT_R + 2]), pdf, False


@inlined
def diffuse_eval(mat, wi, wo):
    """f(wi, wo) |cos wo| = R cos(wo) / pi."""
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return ZERO3
    s = wo[2] * INV_PI
    return (mat[MAT_R] * s, mat[MAT_R + 1] * s, mat[MAT_R + 2] * s)


@inlined
def diffuse_pdf(mat, wi, wo):
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    return wo[2] * INV_PI
