"""The whole book builds with `jupyter-book build -W -n --keep-going` (any warning or failing cell
fails), in quick mode, and -- when Debian's chromium is installed -- the built pages show typeset
formulas and rendered widgets with every non-loopback host unreachable (scripts/check_offline.py).

The build goes to a temporary folder with a fresh, session-wide jupyter cache (conftest's
``quick_book_cache``), so it neither uses nor disturbs the reader's _build/ and its execution cache,
and the chapter tests collected after it reuse its executions instead of running every chapter twice
(under pytest-xdist, tests/conftest.py hands this file and test_book_chapters.py to one worker).
"""
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import toc_files

ROOT = Path(__file__).resolve().parent.parent
#: Objects a chapter imports, which the API page (book/api.md) must document, by their anchors.
API_NAMES = ("gdlearn.integrators.render", "gdlearn.integrators.make", "gdlearn.scene.load.load",
             "gdlearn.reconstruct.poisson_l2", "gdlearn.reconstruct.control_variates",
             "gdlearn.experiments.study.equal_time", "gdlearn.shifts.mis.mis_weight_np",
             "gdlearn.kernels.media.medium.sample_distance_1", "gdlearn.scene.effects.plan")


def toc_pages() -> list[str]:
    """Every page of _toc.yml as its built HTML path (book/preface.md -> book/preface.html)."""
    return [str(p.relative_to(ROOT).with_suffix(".html")) for p in toc_files()]


def _check_offline_module():
    spec = importlib.util.spec_from_file_location("check_offline", ROOT / "scripts" / "check_offline.py")
    co = importlib.util.module_from_spec(spec)
    sys.modules["check_offline"] = co          # dataclasses look their module up there
    spec.loader.exec_module(co)
    return co


@pytest.fixture(scope="module")
def built_book(tmp_path_factory, quick_book_cache):
    out = tmp_path_factory.mktemp("book")
    config = yaml.safe_load((ROOT / "_config.yml").read_text())
    config["execute"]["execute_notebooks"] = "cache"      # the cache starts empty: every chapter runs
    config["execute"]["cache"] = str(quick_book_cache)
    # sort_keys=False: nb_ipywidgets_js is ordered (require.js must load before embed-amd.js)
    (out / "_config.yml").write_text(yaml.safe_dump(config, sort_keys=False))
    env = dict(os.environ, GDLEARN_QUICK="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    jb = Path(sys.executable).with_name("jupyter-book")
    res = subprocess.run([str(jb), "build", "-W", "-n", "--keep-going", "--config", str(out / "_config.yml"),
                          "--path-output", str(out), str(ROOT)], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=1500)
    return res, out / "_build" / "html"


@pytest.mark.notebook
@pytest.mark.timeout(1600)
def test_book_builds_without_warnings(built_book):
    res, html = built_book
    log = res.stdout + res.stderr
    assert res.returncode == 0, "jupyter-book build -W -n --keep-going failed:\n" + log[-6000:]
    assert (html / "index.html").is_file() and (html / "book" / "rendering-as-integration.html").is_file()
    assert (html / "_static" / "mathjax" / "tex-chtml.js").is_file()
    assert (html / "_static" / "ipywidgets" / "embed-amd.js").is_file()


def api_problems(html: Path, names=API_NAMES) -> list[str]:
    """What the built API page lacks: the page itself, or an anchor (autodoc's ``id``) per name."""
    page = html / "book" / "api.html"
    if not page.is_file():
        return [f"{page} was not built (is book/api in _toc.yml?)"]
    text = page.read_text(encoding="utf-8")
    return [f"the API page does not document {n}" for n in names if f'id="{n}"' not in text]


@pytest.mark.notebook
@pytest.mark.timeout(60)
def test_built_book_has_the_api_reference(built_book):
    res, html = built_book
    if not (html / "index.html").is_file():
        pytest.skip("the book did not build (see test_book_builds_without_warnings)")
    assert api_problems(html) == []
    # a docstring's own text made it through autodoc, not only the signature
    assert "screened Poisson" in (html / "book" / "api.html").read_text(encoding="utf-8")


def test_api_check_can_fail(tmp_path):
    """The API check on a planted page: a name missing from it is reported, a missing page too."""
    (tmp_path / "book").mkdir()
    assert api_problems(tmp_path) and "was not built" in api_problems(tmp_path)[0]
    (tmp_path / "book" / "api.html").write_text('<dt id="gdlearn.integrators.render">render()</dt>')
    assert api_problems(tmp_path, ("gdlearn.integrators.render",)) == []
    assert api_problems(tmp_path, ("gdlearn.integrators.render", "gdlearn.integrators.make")) == [
        "the API page does not document gdlearn.integrators.make"]


def test_offline_check_covers_every_page_of_the_toc():
    """The offline check's default pages are _toc.yml's, so a new chapter is checked without an edit."""
    pages = toc_pages()
    assert _check_offline_module().toc_pages() == pages
    assert "book/preface.html" == pages[0] and "book/api.html" in pages and len(pages) == len(set(pages))


@pytest.mark.notebook
@pytest.mark.timeout(1500)
def test_built_book_reads_offline(built_book):
    co = _check_offline_module()
    if co.find_browser() is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    res, html = built_book
    if not (html / "book" / "rendering-as-integration.html").is_file():
        pytest.skip("the book did not build (see test_book_builds_without_warnings)")
    pages = toc_pages()                      # every page of the book, from _toc.yml
    missing = [p for p in pages if not (html / p).is_file()]
    assert not missing, f"pages of _toc.yml not in the built book: {missing}"
    # no screenshots (out=None): nobody looks at them here, and each one is a second Chromium run
    # per page (about half of this test's 117 s, 2026-12-07); scripts/check_offline.py takes them
    results = co.check(pages, use_file=False, out=None, html=html)
    assert [r.page for r in results] == pages
    problems = [f"{r.page}: {r.problems}" for r in results if r.problems]
    assert not problems, "pages that do not read offline:\n" + "\n".join(problems)
    chapter = next(r for r in results if r.page.endswith("rendering-as-integration.html"))
    assert chapter.stores_widgets and chapter.widgets > 0 and chapter.math > 10
