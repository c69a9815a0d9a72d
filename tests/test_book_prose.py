"""Prose that cannot turn false: a comparison word next to a measured value must itself be computed.

The book's numbers come from the chapter's own cells through ``{glue:text}`` (REVIEW-book §3). A
*direction* pasted beside such a number -- "X times **lower**", "**worse** than the primal image",
"the gain is **modest**" -- is a verdict the next build can contradict while the number beside it
changes. Such words belong in a glued :class:`gdlearn.teaching.quick.Sentence` that the cell phrases from the
numbers, where they cannot disagree with them.

The check reads the Markdown of every page listed in _toc.yml, splits it into sentences and fails on
any sentence that holds both a ``{glue}`` value and one of :data:`COMPARISON_WORDS` outside a glued
role. Math, inline code and glued roles are blanked first, so ``{glue:text}`verdict``` (a computed
sentence) and a formula's ``<`` do not count.

A sentence that *defines* a direction rather than asserting one ("above 1 means the gradient-domain
method has the lower error") may be kept by putting a MyST comment line ``% prose-ok: <why>``
directly before its paragraph; the reason is printed by ``pytest -rA`` and read by reviewers.

The self-tests at the bottom plant snippets that must fail and snippets that must pass.
"""
from __future__ import annotations

import re

import pytest

from conftest import ROOT, toc_files

#: Words that state a measured direction or verdict.
COMPARISON_WORDS = re.compile(
    r"\b(lower|higher|better|worse|best|worst|dominat\w*|beats?|beaten|beating|modest\w*|wins?|"
    r"winning|loses?|losing|outperform\w*|more often|less often|as rarely as|as often as|flattens?|"
    r"rises?|rising|cheaper|costlier|faster|slower|far (?:more|less|worse|better))\b",
    re.IGNORECASE)
GLUE = re.compile(r"\{glue(?::\w+)?\}`[^`]*`")
_BLANKS = [
    re.compile(r"\$\$.*?\$\$", re.S),                  # display math
    re.compile(r"\$[^$\n]+\$"),                        # inline math
    re.compile(r"\{(?:math|eq|numref|ref|doc|cite(?::\w+)?)\}`[^`]*`"),
    re.compile(r"```.*?```", re.S),                    # fenced blocks (code, directives' bodies)
    re.compile(r"`[^`\n]*`"),                          # inline code (after roles are handled)
]
SENTENCE_END = re.compile(r"(?<=[.!?])\s+(?=[A-Z(\[*_{`])")
OK_MARK = re.compile(r"^%\s*prose-ok:\s*(.+)$")


def _paragraphs(markdown: str):
    """(first line number, text, reason-or-None) of each paragraph; a ``% prose-ok:`` comment right
    before a paragraph marks it reviewed."""
    out, buf, start, reason, pending = [], [], 0, None, None
    for i, line in enumerate(markdown.splitlines() + [""], 1):
        m = OK_MARK.match(line.strip())
        if m:
            pending = m.group(1)
            continue
        if line.strip():
            if not buf:
                start, reason, pending = i, pending, None
            buf.append(line)
        elif buf:
            out.append((start, "\n".join(buf), reason))
            buf = []
    return out


def prose_problems(markdown: str, where: str = "") -> list[str]:
    """Sentences of ``markdown`` that put a pasted comparison word next to a glued value."""
    problems = []
    for line, para, reason in _paragraphs(markdown):
        if reason is not None or "{glue" not in para:
            continue
        text = GLUE.sub(" GLUED ", para)
        for pat in _BLANKS:
            text = pat.sub(" ", text)
        for sentence in SENTENCE_END.split(text):
            if "GLUED" not in sentence:
                continue
            words = sorted({m.group(0).lower() for m in COMPARISON_WORDS.finditer(sentence)})
            if words:
                snippet = " ".join(sentence.split())[:160]
                problems.append(f"{where}:{line}: pasted {', '.join(repr(w) for w in words)} next to a "
                                f"glued value -- compute it (glue a Sentence) or mark a definition with "
                                f"'% prose-ok: why': \"{snippet}\"")
    return problems


def _markdown_of(path) -> str:
    """The page's prose with line numbers kept: the jupytext header and every block fenced by
    exactly three backticks (code cells, literal includes, shell examples) become blank lines; the
    four-backtick exercise and solution directives keep their prose."""
    lines, out, fence = path.read_text().splitlines(), [], None
    header = lines[:1] == ["---"]
    for i, line in enumerate(lines):
        if header:
            header = not (i > 0 and line == "---")
            out.append("")
            continue
        if fence is None and re.match(r"^```(?!`)", line):
            fence = "```"
            out.append("")
        elif fence is not None:
            fence = None if line.strip() == "```" else fence
            out.append("")
        else:
            out.append("" if line.startswith("````") else line)
    return "\n".join(out)


PAGES = [p for p in toc_files() if p.suffix == ".md"]


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_no_pasted_comparison_next_to_a_glued_value(page):
    problems = prose_problems(_markdown_of(page), str(page.relative_to(ROOT)))
    assert not problems, "prose that a later build can contradict:\n" + "\n".join(problems)


# -- the checker can fail ------------------------------------------------------------------------
PLANTED = [
    # the REVIEW's own examples, each beside a glued number
    "At {glue:text}`spp` spp the image has {glue:text}`r:.1f` times lower relMSE than the primal.",
    "The L2 reconstruction has relMSE {glue:text}`e:.2e`, worse than the primal image alone.",
    "Here the gain is modest: {glue:text}`g:.2f`.",
    "Reconnection dominates at {glue:text}`k:.0f` %.",
    "The curve flattens at the floor ({glue:text}`floor:.2e`).",
    "With {glue:text}`x` the gradient-domain method wins.",
]
FINE = [
    "{glue:text}`verdict`. The numbers come from the cell above.",          # computed verdict
    "The ratio is {glue:text}`r:.2f`; see the table.",                       # a number, no direction
    "A lower relMSE is better. The cell measures it.",                       # no glued value
    "The ratio is {glue:text}`r:.2f` and $a < b$ holds in `lower_bound`.",  # math and code blanked
    "% prose-ok: defines the direction of the ratio\nThe ratio {glue:text}`r:.2f` (above 1: lower error).",
    "The ratio is {glue:text}`r:.2f`.\n\nA smaller relMSE is better in general.",  # another paragraph
]


@pytest.mark.parametrize("snippet", PLANTED)
def test_checker_flags_a_planted_pasted_verdict(snippet):
    problems = prose_problems(snippet, "planted")
    assert problems and "pasted" in problems[0], problems


@pytest.mark.parametrize("snippet", FINE)
def test_checker_accepts_computed_or_unmeasured_prose(snippet):
    assert prose_problems(snippet, "fine") == []
