"""The whole book builds with `jupyter-book build -W -n --keep-going` (any warning or failing cell
fails), in quick mode, and -- when Debian's chromium is installed -- the built pages show typeset
formulas and rendered widgets with every non-loopback host unreachable (scripts/check_offline.py).

The build goes to a temporary folder with a fresh, session-wide jupyter cache (conftest's
``quick_book_cache``), so it neither uses nor disturbs the reader's _build/ and its execution cache,
and the chapter tests collected after it reuse its executions instead of running every chapter twice.
"""
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent


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


@pytest.mark.notebook
@pytest.mark.timeout(600)
def test_built_book_reads_offline(built_book, tmp_path):
    spec = importlib.util.spec_from_file_location("check_offline", ROOT / "scripts" / "check_offline.py")
    co = importlib.util.module_from_spec(spec)
    sys.modules["check_offline"] = co          # dataclasses look their module up there
    spec.loader.exec_module(co)
    if co.find_browser() is None:
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    res, html = built_book
    if not (html / "book" / "rendering-as-integration.html").is_file():
        pytest.skip("the book did not build (see test_book_builds_without_warnings)")
    results = co.check(co.DEFAULT_PAGES, use_file=False, out=tmp_path, html=html)
    for r in results:
        assert not r.problems, f"{r.page}: {r.problems}"
    chapter = next(r for r in results if r.page.endswith("rendering-as-integration.html"))
    assert chapter.stores_widgets and chapter.widgets > 0 and chapter.math > 10
