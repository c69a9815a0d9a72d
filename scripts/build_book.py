#!/usr/bin/env python
"""Build the book: ``jupyter-book build -W -n --keep-going .`` with an execution cache that is wiped
whenever what the chapters' outputs depend on has changed.

Jupyter Book 1 caches executed notebooks (``execute_notebooks: cache`` in _config.yml) keyed on the
notebook's *code* only. The outputs also depend on the environment (numpy, numba, ...), on gdlearn's
own code and the scene files, and on quick mode; a cache hit across a change of any of these would
show stale figures. So this script fingerprints them -- pyproject.toml, the Python version, every
installed distribution's name and version, the contents of gdlearn/ and scenes/, and
``GDLEARN_QUICK`` -- and clears ``_build/.jupyter_cache`` when the fingerprint differs from the one
stored beside it, together with Sphinx's doctrees (which hold every page's outputs as well; without
them gone an unchanged page would keep its old figures). A text-only edit of a chapter still hits
the cache.

Usage (the Makefile's ``make book`` calls the first form)::

    .venv/bin/python scripts/build_book.py            # full budgets
    .venv/bin/python scripts/build_book.py --quick    # GDLEARN_QUICK=1 budgets (what CI executes)
    .venv/bin/python scripts/build_book.py --fresh    # wipe the cache whatever the fingerprint

Prints the build's wall time; exit status is jupyter-book's (non-zero on any warning or failing cell).
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.metadata as md
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / "_build" / ".jupyter_cache"
STAMP = ROOT / "_build" / ".jupyter_cache.fingerprint"
#: Sphinx's pickled environment holds every page's executed outputs too: an unchanged chapter would
#: keep its old figures from there even with the execution cache gone. Wiped together with CACHE.
DOCTREES = ROOT / "_build" / ".doctrees"
#: Trees whose content the chapters' outputs depend on (besides the chapters themselves).
SOURCE_TREES = ("gdlearn", "scenes")
SKIP_SUFFIXES = (".pyc", ".nbi", ".nbc")          # byte code and numba's own caches


def _tree_digest(h, folder: Path) -> None:
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        if path.suffix in SKIP_SUFFIXES or "__pycache__" in path.parts:
            continue
        h.update(str(path.relative_to(ROOT)).encode())
        h.update(hashlib.sha256(path.read_bytes()).digest())


def fingerprint(quick: bool) -> str:
    """sha256 of everything the cached outputs depend on besides the notebooks' code."""
    h = hashlib.sha256()
    h.update(f"python {platform.python_version()} quick={quick}\n".encode())
    h.update((ROOT / "pyproject.toml").read_bytes())
    for dist in sorted(f"{d.metadata['Name']}=={d.version}".lower() for d in md.distributions()):
        h.update(dist.encode() + b"\n")
    for tree in SOURCE_TREES:
        if (ROOT / tree).is_dir():
            _tree_digest(h, ROOT / tree)
    return h.hexdigest()


def refresh_cache(quick: bool, fresh: bool) -> str:
    """Wipe the execution cache if the fingerprint changed (or ``fresh``); return why/what happened."""
    new = fingerprint(quick)
    old = STAMP.read_text().strip() if STAMP.is_file() else None
    if fresh or old != new:
        shutil.rmtree(CACHE, ignore_errors=True)
        shutil.rmtree(DOCTREES, ignore_errors=True)
        STAMP.parent.mkdir(parents=True, exist_ok=True)
        STAMP.write_text(new + "\n")
        return "cleared (" + ("--fresh" if fresh else "no fingerprint yet" if old is None else
                              "environment, gdlearn, scenes or quick mode changed") + ")"
    return "kept (fingerprint unchanged)"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="execute chapters with GDLEARN_QUICK=1")
    ap.add_argument("--fresh", action="store_true", help="wipe the execution cache first")
    ap.add_argument("extra", nargs="*", help="further arguments for jupyter-book build")
    args = ap.parse_args(argv)

    env = dict(os.environ)
    if args.quick:
        env["GDLEARN_QUICK"] = "1"
    quick = env.get("GDLEARN_QUICK", "").strip().lower() in {"1", "true", "yes", "on"}
    print(f"build_book: execution cache {refresh_cache(quick, args.fresh)}; "
          f"{'quick' if quick else 'full'} budgets", flush=True)
    # Chapters import gdlearn from the repository even without `pip install -e .`.
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    jb = Path(sys.executable).with_name("jupyter-book")
    cmd = [str(jb) if jb.exists() else "jupyter-book", "build", "-W", "-n", "--keep-going",
           *args.extra, str(ROOT)]
    t0 = time.perf_counter()
    rc = subprocess.call(cmd, cwd=ROOT, env=env)
    print(f"build_book: jupyter-book exited {rc} after {time.perf_counter() - t0:.1f} s; "
          f"open {ROOT / '_build' / 'html' / 'index.html'}", flush=True)
    return rc


if __name__ == "__main__":
    sys.exit(main())
