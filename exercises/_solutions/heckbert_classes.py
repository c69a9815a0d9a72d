"""Reference solution of the exercise "heckbert-classes" (the book shows it in a dropdown).

gdlearn classifies a path incrementally while it traces it (``gdlearn.kernels.pathclass``, a
packed integer state); here the same classes are written as regular expressions over the whole
Heckbert string, read from the light L to the eye E.
"""
import re

NAMES = ("emission", "direct-lighting", "diffuse-interreflection", "glossy", "specular", "caustics",
         "single-scattering", "multiple-scattering", "volume-caustics")

REGEX = {
    "emission": r"LE",
    "direct-lighting": r"L[DGS]E",                       # one surface vertex of any kind
    "single-scattering": r"LME",                         # one medium vertex
    "caustics": r"LS+[DG][DGSM]*E",                      # specular chain from the light onto D or G
    "volume-caustics": r"LS+M[DGSM]*E",                  # ... into a medium
    # two or more vertices, some in a medium, not starting with a specular chain (that would be a
    # caustic or a volume caustic: the first non-S vertex is D, G or M)
    "multiple-scattering": r"L(?=[DGSM]*M)[DGM][DGSM]+E",
    # two or more surface vertices, some specular, no medium, not a caustic: all specular, or the
    # first vertex from the light is non-specular
    "specular": r"L(?:S{2,}|[DG][DGS]*S[DGS]*)E",
    "glossy": r"L(?=[DG]*G)[DG]{2,}E",                   # no S, no M, some G
    "diffuse-interreflection": r"LD{2,}E",
}


def class_regex(name: str) -> str:
    return REGEX[name]


def classify(path: str) -> str:
    hits = [n for n in NAMES if re.fullmatch(REGEX[n], path)]
    if len(hits) != 1:
        raise ValueError(f"{path!r} matches {hits}")
    return hits[0]
