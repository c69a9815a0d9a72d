"""Quick mode: one switch that scales every chapter's budget down so CI can execute the whole book.

The book's chapters are executable notebooks. Built for a reader (``make book``) they spend real
budgets -- hundreds of samples per pixel, seconds of equal-time rendering -- so that their figures
show converged behaviour. Executed by the tests (``make test``, environment ``GDLEARN_QUICK=1``)
each chapter must finish within about two minutes on two cores, so every budget a chapter spends
goes through :func:`budget`::

    from gdlearn.teaching.quick import budget, caption
    spp = budget(full=256, quick=8)
    frame = render(make("pt", scene, seed=1), spp=spp)
    ax.set_title(caption("Cornell box", spp=spp, seed=1))   # says which budget made the figure

Captions must say which budget produced each figure, and a quick build must not pass off
an 8-spp figure as the 256-spp one: :func:`caption` appends "(quick mode)" when it is on.
"""
from __future__ import annotations

import os

#: The environment variable that turns quick mode on ("1", "true", "yes", "on"; anything else: off).
ENV_VAR = "GDLEARN_QUICK"

_TRUE = {"1", "true", "yes", "on"}


def is_quick() -> bool:
    """True when ``GDLEARN_QUICK`` asks for quick mode. Read on every call (no cached global), so a
    test may switch it with ``monkeypatch.setenv`` and a kernel inherits it from its parent."""
    return os.environ.get(ENV_VAR, "").strip().lower() in _TRUE


def budget(full, quick):
    """``full`` for the reader's build, ``quick`` under ``GDLEARN_QUICK=1``.

    Works for any budget kind (samples per pixel, seconds, resolution, number of seeds, a tuple of
    spp levels). Both must be given: a chapter states its quick budget where it states its real one,
    so a reviewer sees both. ``quick`` may not exceed ``full`` for numbers -- that would make CI
    slower than the book, which is always a typo.
    """
    if isinstance(full, (int, float)) and isinstance(quick, (int, float)):
        if quick > full:
            raise ValueError(f"quick budget {quick} exceeds the full budget {full}; "
                             "quick mode must be the smaller one (swap the arguments?)")
        if quick <= 0:
            raise ValueError(f"quick budget must be positive, got {quick}")
    return quick if is_quick() else full


def describe(**spent) -> str:
    """The budget as caption text: ``describe(spp=16, seed=1)`` -> ``"16 spp, seed 1"``.

    Known keys print in the book's usual words (``spp``, ``seconds`` -> "2.0 s", ``seed``,
    ``res`` -> "64x64 px", ``seeds`` -> "8 seeds", ``n`` -> "N = 1000"); others as ``key value``.
    Quick mode is appended, so a CI-built figure never claims the full budget.
    """
    words = []
    for key, value in spent.items():
        if key == "spp":
            words.append(f"{value} spp")
        elif key == "seconds":
            words.append(f"{float(value):.1f} s")
        elif key == "res":
            w, h = (value, value) if isinstance(value, int) else value
            words.append(f"{w}x{h} px")
        elif key == "seeds":
            words.append(f"{value} seeds")
        elif key == "n":
            words.append(f"N = {value}")
        else:
            words.append(f"{key} {value}")
    if is_quick():
        words.append("quick mode")
    return ", ".join(words)


def caption(text: str, **spent) -> str:
    """A figure caption that ends with its budget: ``"Cornell box (16 spp, seed 1)"``."""
    return f"{text} ({describe(**spent)})" if spent or is_quick() else text


class Sentence:
    """A sentence computed by a chapter, for ``glue(name, Sentence(text), display=False)``.

    ``{glue:text}`` shows the repr of the glued object, and a ``str``'s repr carries quotes; this
    one's repr is the text itself. Chapters phrase their verdicts from the numbers of the build
    with it, instead of pasting a verdict that a later build might contradict."""

    def __init__(self, text: str):
        self.text = str(text)

    def __repr__(self) -> str:
        return self.text


def times(ratio: float, above: str, below: str, fmt: str = ".1f", tie: float = 0.0) -> Sentence:
    """A measured ratio in words whose direction follows the number: ``times(3.2, "lower", "higher")``
    -> "3.2 times lower", ``times(0.5, "lower", "higher")`` -> "2.0 times higher". Within ``tie``
    of 1 (e.g. 0.05) it says "about as low/high" -- "about the same" -- instead of a direction."""
    r = float(ratio)
    if not r > 0 or r != r:
        return Sentence(f"not measurable (ratio {r})")
    if tie and abs(r - 1) <= tie:
        return Sentence(f"about the same ({r:{fmt}} times)")
    return Sentence(f"{r:{fmt}} times {above}" if r >= 1 else f"{1 / r:{fmt}} times {below}")
