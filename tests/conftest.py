"""Shared test machinery. Its main job: collect the book's chapters (MyST-markdown notebooks, which
nbmake cannot collect) so that the README's test command executes every chapter in quick mode.

Any test that takes a ``chapter`` argument is run once per notebook chapter listed in _toc.yml
(a chapter without a jupytext header, such as the status page, is plain Markdown and is skipped);
:func:`execute_chapter` runs one with jupytext + nbclient under ``GDLEARN_QUICK=1``, in book/ as
Jupyter Book does, so the tests execute exactly what the book build executes.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

# Two pytest-xdist workers share two cores, each running numba's OpenMP loops on two threads: GNU
# OpenMP's default lets a thread that waits at a barrier spin, taking the core the other worker's
# thread needs. Passive waiting sleeps at once. Set before numba loads its threading layer (the first
# parallel loop); the chapters' kernels, started by the book build, inherit it.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

ROOT = Path(__file__).resolve().parent.parent
BOOK = ROOT / "book"
#: Seconds one cell may run in quick mode before the test fails (quick chapters take ~10-60 s in all).
CELL_TIMEOUT = 300


def toc_files() -> list[Path]:
    """Every file _toc.yml lists (root first), in book order, as absolute paths with suffix."""
    import yaml

    toc = yaml.safe_load((ROOT / "_toc.yml").read_text())
    names = [toc["root"]]

    def walk(entries):                 # jb-book: chapters -> sections, or parts -> chapters
        for entry in entries or []:
            if "file" in entry:
                names.append(entry["file"])
            walk(entry.get("sections"))

    walk(toc.get("chapters"))
    for part in toc.get("parts", []):
        walk(part.get("chapters"))
    out = []
    for name in names:
        path = ROOT / name
        out.append(path if path.suffix else path.with_suffix(".md"))
    return out


def is_notebook(path: Path) -> bool:
    """A MyST notebook starts with a YAML header naming a jupytext format and a kernel."""
    head = path.read_text(encoding="utf-8")[:600]
    return head.startswith("---") and "jupytext" in head and "kernelspec" in head


def notebook_chapters() -> list[Path]:
    return [p for p in toc_files() if p.suffix == ".md" and p.is_file() and is_notebook(p)]


#: Test files that share one xdist worker (the ``book`` work unit), in this order: the quick-mode book
#: build fills this session's jupyter cache (``quick_book_cache``: session-scoped, so one per worker)
#: and the chapter tests read it. Apart, the chapter tests would execute every chapter a second time.
BOOK_FILES = ("tests/test_book_build.py", "tests/test_book_chapters.py")


#: Files handed out right after the book, in this order. Most of the suite's time is numba compiling
#: kernels, once per scene form, into the cache every process shares (GDLEARN_CACHE). The book runs
#: its chapters in name order: pt's and gpt's first, the photon estimators' last (gradient-photons,
#: gradient-volume-photons, ~8 of its 15 min cold). While it compiles the first, the other worker
#: compiles the photon estimators' kernels on the same scenes, so the book finds them in the cache;
#: the path tracers' tests, after these, find what the book compiled. In name order both workers
#: compiled pt and gpt at once, then both the photon kernels.
EARLY_FILES = ("tests/test_photon_fast_passes.py", "tests/test_gpm.py", "tests/test_sppm.py", "tests/test_gvpm.py",
               "tests/test_gbre.py", "tests/test_volume_estimates.py", "tests/test_vpm_bre_cli.py")


def pytest_collection_modifyitems(config, items):
    """The book's files first, then :data:`EARLY_FILES`, then the rest in name order (a stable sort:
    tests keep their order within a file). Under xdist every worker sorts alike, and the scheduler
    below hands the files out in this order."""
    rank = {f: i for i, f in enumerate(BOOK_FILES + EARLY_FILES)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::", 1)[0], len(rank)))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist's ``--dist loadfile`` (pyproject.toml's addopts), with the two book files as one
    work unit handed out first (it is the longest: 15 of the suite's 32 min on one worker, this
    session's 2-core machine, 2026-12-07).

    Files stay whole so that a module-scoped fixture (a render several tests check) runs once, not
    once per worker. Work units go out in collection order (:func:`pytest_collection_modifyitems`)
    instead of xdist's default of the most tests first."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class BookTogether(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = super()._split_scope(nodeid)
            return "book" if path in BOOK_FILES else path

    config.option.loadscopereorder = False
    return BookTogether(config, log)


def pytest_generate_tests(metafunc):
    if "chapter" in metafunc.fixturenames:
        chapters = notebook_chapters()
        metafunc.parametrize("chapter", chapters, ids=[str(p.relative_to(ROOT)) for p in chapters])


@pytest.fixture(scope="session")
def quick_book_cache(tmp_path_factory) -> Path:
    """A jupyter-cache folder for this test session's quick-mode executions.

    The quick-mode book build (tests/test_book_build.py, collected first) executes every chapter and
    stores the executed notebooks here; the chapter tests then check those outputs instead of running
    each chapter a second time (:func:`executed_by_book_build`). A session fixture is one per
    pytest-xdist worker: :func:`pytest_xdist_make_scheduler` keeps both files on one. Run on their own, the chapter tests
    find the folder empty and execute the chapters themselves."""
    return tmp_path_factory.mktemp("quick_jupyter_cache")


def executed_by_book_build(path: Path, cache_dir: Path):
    """The notebook of chapter ``path`` with the outputs the quick-mode book build produced, or None
    when that build did not run (or did not finish this chapter) in this session.

    The match is jupyter-cache's own: a hash of the code cells and the kernelspec, which myst-nb
    (the build) and jupytext (:func:`execute_chapter`) read identically from a MyST chapter."""
    import jupytext
    from jupyter_cache import get_cache

    if not (Path(cache_dir) / "global.db").is_file():
        return None
    cache = get_cache(str(cache_dir))
    try:
        record = cache.match_cache_notebook(jupytext.read(path))
    except KeyError:
        return None
    return cache.get_cache_bundle(record.pk).nb


def execute_chapter(path: Path, quick: bool = True):
    """Execute one chapter like the book build does (cwd book/, gdlearn importable); return
    (notebook with outputs, wall seconds). Raises nbclient's CellExecutionError on a failing cell."""
    import jupytext
    from nbclient import NotebookClient

    nb = jupytext.read(path)
    env_before = dict(os.environ)
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    if quick:
        os.environ["GDLEARN_QUICK"] = "1"
    else:
        os.environ.pop("GDLEARN_QUICK", None)
    # The kernel is this interpreter (the .venv), so the chapter sees the same packages as the tests.
    client = NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    try:
        client.execute()
    finally:
        os.environ.clear()
        os.environ.update(env_before)
    return nb, time.perf_counter() - t0


#: Bound on one exercise check in a child process (it may JIT-compile numba kernels cold on a busy
#: 2-core machine). It only bounds a hang: no assertion depends on how long the child took.
EXERCISE_CHECK_TIMEOUT = 1800


def check_exercise_source(tmp_path: Path, name: str, source: str) -> tuple[int, str]:
    """Run ``gdlearn check NAME`` in a child process on a copy of exercise ``name`` whose stub is
    replaced by ``source``; return (exit status, printed report). Tests use it to show that a
    planted wrong answer fails the checks and the right one passes."""
    import shutil
    import subprocess
    import sys
    work = tmp_path / "exercises"
    shutil.copytree(ROOT / "exercises" / name, work / name)
    (work / "_solutions").mkdir()
    (work / name / f"{name.replace('-', '_')}.py").write_text(source)
    code = (f"import pathlib, sys; import gdlearn.teaching.exercises as e; e.EXERCISES_DIR = pathlib.Path({str(work)!r}); "
            f"e.SOLUTIONS_DIR = e.EXERCISES_DIR / '_solutions'; r = e.check({name!r}); print(r.text()); "
            "sys.exit(0 if r.ok else 1)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=EXERCISE_CHECK_TIMEOUT)
    return res.returncode, res.stdout + res.stderr


def gradient_residuals(frame):
    """Channel means of a gradient frame against its own base estimate: (gx - FD_x(base),
    gy - FD_y(base), primal - base, gx, FD_x(base)), forward differences zero on the last
    column / row (the fixed-radius unbiasedness checks of the photon estimators)."""
    import numpy as np
    pb = frame.images["primal_base"].mean(-1)
    fdx = np.zeros_like(pb)
    fdx[:, :-1] = pb[:, 1:] - pb[:, :-1]
    fdy = np.zeros_like(pb)
    fdy[:-1] = pb[1:] - pb[:-1]
    gx, gy = frame.gx.mean(-1), frame.gy.mean(-1)
    return np.stack([gx - fdx, gy - fdy, frame.primal.mean(-1) - pb, gx, fdx])


def pass_replicates(integ, passes: int):
    """Each pass of a fixed-radius run (alpha = 1: every pass an independent estimate of the same
    blurred image) as a replicate: (passes, 2, H, W) of the pass's own gx - FD_x(base) and
    gy - FD_y(base), channel means (the frame holds running means, so a pass is p x mean_p -
    (p - 1) x mean_{p-1}), and the last frame."""
    import numpy as np
    reps, prev = [], 0.0
    for p in range(1, passes + 1):
        f = integ.step()
        cur = p * np.stack([f.gx.mean(-1), f.gy.mean(-1), f.images["primal_base"].mean(-1)])
        one, prev = cur - prev, cur
        fdx = np.zeros_like(one[2])
        fdx[:, :-1] = one[2][:, 1:] - one[2][:, :-1]
        fdy = np.zeros_like(one[2])
        fdy[:-1] = one[2][1:] - one[2][:-1]
        reps.append((one[0] - fdx, one[1] - fdy))
    return np.array(reps), f


def render_cli(tmp_path: Path, args: list[str], res: int, buffers: tuple[str, ...]):
    """``gdlearn render ARGS --set res=RES --out img.npy --buffers b``: the image is finite, positive
    and RES x RES, and every named buffer was written (the CLI checks of the gradient photon
    estimators). Returns the image."""
    import subprocess
    import sys
    import numpy as np
    out = tmp_path / "img.npy"
    p = subprocess.run([sys.executable, "-m", "gdlearn", "render", *args, "--set", f"res={res}", "--no-progress",
                        "--out", str(out), "--buffers", str(tmp_path / "b")], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    img = np.load(out)
    assert img.shape == (res, res, 3) and np.isfinite(img).all() and img.mean() > 0
    for name in buffers:
        assert (tmp_path / "b" / f"{name}.npy").exists(), name
    return img
