"""Checked exercises: find them, load the module under test, run their tests with readable feedback.

Layout (see exercises/README.md)::

    exercises/<name>/README.md             the task
    exercises/<name>/<module>.py           the stub the student edits (module = name with - -> _)
    exercises/<name>/test_<module>.py      the tests; each test's docstring is its feedback line
    exercises/_solutions/<module>.py       the reference solution -- solutions live in one place

A test file gets its target with ``ex = load_target("<name>")``: the student's stub, or the solution
when ``GDLEARN_EXERCISE_TARGET=solution`` (CI runs every exercise that way, so none can rot).
``gdlearn check <name>`` calls :func:`check`, which runs pytest on the exercise and prints one line
per test -- its docstring, and for a failure the assertion's message -- instead of tracebacks.
"""
from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

#: Where the exercises live: the repository's exercises/ folder, beside the gdlearn package.
EXERCISES_DIR = Path(__file__).resolve().parent.parent / "exercises"
SOLUTIONS_DIR = EXERCISES_DIR / "_solutions"
#: Environment variable that points the tests at the reference solution instead of the stub.
TARGET_ENV = "GDLEARN_EXERCISE_TARGET"


def module_name(name: str) -> str:
    """The Python module of exercise ``name``: ``"cosine-hemisphere"`` -> ``"cosine_hemisphere"``."""
    return name.replace("-", "_")


def list_exercises() -> list[str]:
    """Names of all exercises (folders of exercises/ that hold a README.md), sorted."""
    if not EXERCISES_DIR.is_dir():
        return []
    return sorted(p.name for p in EXERCISES_DIR.iterdir()
                  if p.is_dir() and not p.name.startswith(("_", ".")) and (p / "README.md").is_file())


def _require(name: str) -> Path:
    folder = EXERCISES_DIR / name
    if name not in list_exercises():
        known = ", ".join(list_exercises()) or "(none found)"
        raise ValueError(f"no exercise named {name!r} in {EXERCISES_DIR}; known exercises: {known}")
    return folder


def target_path(name: str, solution: bool | None = None) -> Path:
    """The file under test: the stub, or the solution (``solution=None``: decided by the env var)."""
    if solution is None:
        solution = os.environ.get(TARGET_ENV, "").strip().lower() == "solution"
    folder = _require(name)
    path = (SOLUTIONS_DIR if solution else folder) / f"{module_name(name)}.py"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing; restore it from git (`git checkout -- {path}`)")
    return path


def load_target(name: str, solution: bool | None = None):
    """Import the module under test from its file (a fresh module object every call)."""
    path = target_path(name, solution)
    tag = "solution" if path.parent == SOLUTIONS_DIR else "stub"
    spec = importlib.util.spec_from_file_location(f"gdlearn_exercise_{module_name(name)}_{tag}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@dataclass
class Outcome:
    """One test's result: ``label`` (its docstring's first line), ``passed``, and ``message``
    (for a failure: the assertion's text or the exception's one-line summary)."""
    label: str
    passed: bool
    message: str = ""


@dataclass
class Report:
    name: str
    target: Path
    outcomes: list[Outcome] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)     # collection errors (e.g. a SyntaxError)

    @property
    def ok(self) -> bool:
        return not self.errors and bool(self.outcomes) and all(o.passed for o in self.outcomes)

    def text(self) -> str:
        lines = [f"exercise {self.name}: testing {self.target}"]
        lines += [f"  could not load the tests: {e}" for e in self.errors]
        for o in self.outcomes:
            lines.append(f"  {'ok  ' if o.passed else 'FAIL'}  {o.label}")
            if not o.passed and o.message:
                lines += [f"          {line}" for line in o.message.splitlines()[:6]]
        passed = sum(o.passed for o in self.outcomes)
        lines.append(f"{passed} of {len(self.outcomes)} checks passed."
                     + (" Well done." if self.ok else " Read the messages above, edit, run again."))
        return "\n".join(lines)


def _crash_message(report) -> str:
    crash = getattr(report.longrepr, "reprcrash", None)
    msg = crash.message if crash is not None else str(report.longrepr).strip().splitlines()[-1]
    # "AssertionError: text\nassert ..." -> the student's part is the text before pytest's rewrite.
    msg = msg.split("\nassert ")[0]
    return msg.removeprefix("AssertionError: ")


class _Collector:
    """pytest plugin that records each test's outcome and docstring."""

    def __init__(self):
        self.docs: dict[str, str] = {}
        self.outcomes: list[Outcome] = []
        self.errors: list[str] = []

    def pytest_collection_modifyitems(self, items):
        for item in items:
            doc = (getattr(item, "obj", None).__doc__ or "") if hasattr(item, "obj") else ""
            self.docs[item.nodeid] = doc.strip().splitlines()[0] if doc.strip() else item.name

    def pytest_runtest_logreport(self, report):
        label = self.docs.get(report.nodeid, report.nodeid)
        if report.when == "call" or (report.when == "setup" and report.failed):
            self.outcomes.append(Outcome(label, report.passed, "" if report.passed else _crash_message(report)))

    def pytest_collectreport(self, report):
        if report.failed:
            self.errors.append(_crash_message(report))


def check(name: str, solution: bool = False, verbose: bool = False) -> Report:
    """Run exercise ``name``'s tests against the stub (or the solution) and return a :class:`Report`.

    ``verbose`` lets pytest print its own output (tracebacks) as well.
    """
    import pytest

    folder = _require(name)
    report = Report(name, target_path(name, solution))
    collector = _Collector()
    args = [str(folder), "-p", "no:cacheprovider", "-o", "addopts=", "--rootdir", str(EXERCISES_DIR),
            "-q" if verbose else "--tb=no"]
    old = os.environ.get(TARGET_ENV)
    os.environ[TARGET_ENV] = "solution" if solution else "stub"
    try:
        sink = contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())
        with sink:
            pytest.main(args, plugins=[collector])
    finally:
        if old is None:
            os.environ.pop(TARGET_ENV, None)
        else:
            os.environ[TARGET_ENV] = old
        for mod in [m for m in sys.modules if m.startswith("test_" + module_name(name))]:
            del sys.modules[mod]             # a second check in this process re-imports the tests
    report.outcomes, report.errors = collector.outcomes, collector.errors
    return report


__all__ = ["EXERCISES_DIR", "SOLUTIONS_DIR", "TARGET_ENV", "list_exercises", "target_path",
           "load_target", "check", "Report", "Outcome", "module_name"]
