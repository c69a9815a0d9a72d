"""Image input/output: EXR, tone-mapped PNG, npy (see :mod:`gdlearn.io.images`)."""
from gdlearn.io.images import read_image, write_image  # noqa: F401
from gdlearn.io.tonemap import tonemap  # noqa: F401
