"""Exercise "heckbert-classes" (chapter: The effects a scene calls for). Fill in the two functions.

Run ``gdlearn check heckbert-classes`` to test them (see README.md).
"""
import re


def class_regex(name: str) -> str:
    """The regular expression (for re.fullmatch) of effect class ``name`` over strings L...E."""
    raise NotImplementedError("class_regex is not written yet (see README.md)")


def classify(path: str) -> str:
    """The effect class of ``path`` (e.g. "LSDE" -> "caustics"), from class_regex."""
    raise NotImplementedError("classify is not written yet (see README.md)")
