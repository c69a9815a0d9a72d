"""Book / library drift: a chapter must import its algorithms from gdlearn, never define them.

The check parses every code cell of every notebook chapter (AST, after dropping IPython magics)
and flags, with the chapter, the cell and the line:

* numba in a chapter (``import numba``, ``@njit``/``@jit``/``@vectorize``...): compiled kernels are
  package code by definition;
* a function or class named like an algorithm -- estimator, integrator, renderer, tracer, sampler,
  solver, reconstruction, Poisson, shift, Jacobian, radiance, photon, BSDF, MIS, ... -- or a class
  deriving from an ``...Integrator``;
* any function longer than :data:`MAX_HELPER_LINES` lines: a chapter may define small helpers
  (an integrand, a plotting function), anything longer is an algorithm that belongs in gdlearn.

The self-tests below feed the checker snippets that must pass and snippets that must fail.
"""
from __future__ import annotations

import ast
import re

import pytest


#: Words that name rendering / reconstruction algorithms (matched in function and class names).
ALGORITHM_WORDS = re.compile(
    r"estimat|integrat|render|trac(e|er|ing)|sampl|solve|solver|reconstruct|poisson|screened|"
    r"shift|jacobian|radiance|photon|bsdf|brdf|phase|mis_|_mis|heuristic|control_variate|"
    r"gradient|path|beam|plane|gather|kernel|relmse|warp|intersect|bvh", re.IGNORECASE)
NUMBA_DECORATORS = {"njit", "jit", "vectorize", "guvectorize", "stencil", "cfunc", "prange"}
#: Longest function a chapter may define (lines, decorators and docstring included).
MAX_HELPER_LINES = 12


def _strip_magics(source: str) -> str:
    # IPython magics / shell escapes are not Python; blank them so line numbers stay right.
    return "\n".join("" if line.lstrip().startswith(("%", "!")) else line for line in source.splitlines())


def _name(node) -> str:
    node = node.func if isinstance(node, ast.Call) else node
    return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")


def drift_problems(source: str) -> list[str]:
    """What in this cell's code defines an algorithm instead of importing it (empty: fine)."""
    tree = ast.parse(_strip_magics(source))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            if any(m.split(".")[0] == "numba" for m in mods):
                found.append(f"line {node.lineno}: imports numba (compiled kernels belong in gdlearn)")
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            for dec in node.decorator_list:
                if _name(dec) in NUMBA_DECORATORS:
                    found.append(f"line {node.lineno}: @{_name(dec)} on {node.name} (numba kernel in a chapter)")
            if ALGORITHM_WORDS.search(node.name):
                found.append(f"line {node.lineno}: defines {node.name!r}, named like an algorithm; "
                             "import it from gdlearn instead")
            first = min([node.lineno] + [d.lineno for d in node.decorator_list])
            if not isinstance(node, ast.ClassDef) and node.end_lineno - first + 1 > MAX_HELPER_LINES:
                found.append(f"line {node.lineno}: function {node.name!r} is {node.end_lineno - first + 1} "
                             f"lines (> {MAX_HELPER_LINES}): algorithms belong in gdlearn")
        if isinstance(node, ast.ClassDef) and any(_name(b).endswith("Integrator") for b in node.bases):
            found.append(f"line {node.lineno}: class {node.name} subclasses an integrator")
    return found


def _code_cells(path):
    import jupytext

    nb = jupytext.read(path)
    return [(i, c.source) for i, c in enumerate(nb.cells) if c.cell_type == "code"]


def test_chapter_imports_its_algorithms_from_gdlearn(chapter):
    problems = [f"{chapter.name}, code cell {i}: {p}" for i, src in _code_cells(chapter)
                for p in drift_problems(src)]
    assert not problems, "book/library drift:\n" + "\n".join(problems)


# -- the checker can fail --------------------------------------------------------------------------
FINE = [
    "def f(x):\n    return np.sin(np.pi * x)\n",
    "def histogram_at(n):\n    fig, ax = plt.subplots()\n    return fig\n",
    "%matplotlib inline\nfrom gdlearn.integrators import make, render\nframe = render(make('pt', s), spp=4)\n",
    "import numpy as np\nx = np.random.default_rng(1).random(10)\nprint(x.mean())\n",
]
DRIFTING = [
    ("from numba import njit\n", "imports numba"),
    ("import numba\n", "imports numba"),
    ("@njit(cache=True)\ndef g(x):\n    return x\n", "@njit"),
    ("@nb.jit\ndef g(x):\n    return x\n", "@jit"),
    ("def estimate_pixel(x):\n    return x\n", "named like an algorithm"),
    ("def poisson_solve(b):\n    return b\n", "named like an algorithm"),
    ("def trace(ray):\n    return ray\n", "named like an algorithm"),
    ("class MyTracer(ProgressiveIntegrator):\n    pass\n", "subclasses an integrator"),
    ("def helper(x):\n" + "    x = x + 1\n" * 14 + "    return x\n", "lines (>"),
]


@pytest.mark.parametrize("source", FINE)
def test_checker_accepts_helpers_and_imports(source):
    assert drift_problems(source) == []


@pytest.mark.parametrize("source, expected", DRIFTING)
def test_checker_flags_algorithms_in_chapters(source, expected):
    problems = drift_problems(source)
    assert problems and any(expected in p for p in problems), problems
