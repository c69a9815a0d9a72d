#!/usr/bin/env python
"""Does the built book read offline? Headless Chromium loads pages of _build/html with every
non-loopback host made unresolvable, and we check that MathJax typeset the formulas and that the
stored ipywidgets state rendered as widgets. Screenshots are written for a person to look at.

    .venv/bin/python scripts/check_offline.py                       # every page of _toc.yml, on 127.0.0.1
    .venv/bin/python scripts/check_offline.py --file                # load through file:// instead
    .venv/bin/python scripts/check_offline.py --out /tmp/shots book/preface.html

Needs Debian's ``chromium`` (``apt-get install -y chromium``); exits 3 when it is missing, 1 when a
page fails a check, 0 when all pass. ``tests/test_book_offline.py`` runs it when chromium is present.

What is checked, per page, in the DOM after a virtual-time budget (``--dump-dom``):
* math: the page's TeX became ``mjx-container`` elements (MathJax 3 ran, from the vendored copy);
* widgets (pages that store widget state): html-manager rendered ``.jupyter-widgets`` views, and
  did not replace them with its "Error rendering Jupyter widget" message;
* nothing: no ``<script src>`` on the page points off-site (a CDN would be dead offline).
"""
from __future__ import annotations

import argparse
import functools
import http.server
import re
import shutil
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HTML = ROOT / "_build" / "html"
TOC = ROOT / "_toc.yml"
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: Every host but the loopback resolves to nothing: a page that needs a CDN visibly fails.
NO_NETWORK = "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1"
BUDGET_MS = 20000        # virtual time for MathJax + html-manager to finish (they are fast: ~1-2 s)


@dataclass
class PageResult:
    page: str
    math: int = 0                       # mjx-container elements after typesetting
    tex_left: int = 0                   # math spans still holding raw TeX delimiters
    widgets: int = 0                    # rendered widget views
    widget_errors: int = 0
    stores_widgets: bool = False
    has_math: bool = True               # the page holds TeX for MathJax (a status table may not)
    offsite_scripts: list[str] = field(default_factory=list)
    screenshot: Path | None = None

    @property
    def problems(self) -> list[str]:
        out = []
        if (self.has_math and self.math == 0) or self.tex_left:
            out.append(f"MathJax did not typeset ({self.math} mjx-container, {self.tex_left} raw TeX spans)")
        if self.stores_widgets and (self.widgets == 0 or self.widget_errors):
            out.append(f"widgets did not render ({self.widgets} views, {self.widget_errors} errors)")
        if self.offsite_scripts:
            out.append("scripts load from off-site: " + ", ".join(self.offsite_scripts))
        return out


def toc_pages(toc: Path = TOC) -> list[str]:
    """Every page _toc.yml lists (root first, book order) as its built HTML path, e.g.
    ``book/preface.html``: the offline check covers the whole book, not a hand-kept subset."""
    import yaml

    data = yaml.safe_load(toc.read_text())
    names = [data["root"]]

    def walk(entries):                 # jb-book: chapters -> sections, or parts -> chapters
        for entry in entries or []:
            if "file" in entry:
                names.append(entry["file"])
            walk(entry.get("sections"))

    walk(data.get("chapters"))
    for part in data.get("parts", []):
        walk(part.get("chapters"))
    return [str(Path(n).with_suffix(".html")) for n in names]


def find_browser() -> str | None:
    return next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)


def _chromium(browser: str, url: str, *extra: str, timeout: float = 120) -> str:
    profile = tempfile.mkdtemp(prefix="gdlearn-chromium-")
    cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--no-first-run", "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage",
           "--hide-scrollbars", f"--user-data-dir={profile}", NO_NETWORK,
           f"--virtual-time-budget={BUDGET_MS}", *extra, url]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    return res.stdout


def inspect(browser: str, base: str, page: str, out: Path | None, html: Path = HTML) -> PageResult:
    raw = (html / page).read_text(encoding="utf-8")
    res = PageResult(page, stores_widgets="application/vnd.jupyter.widget-state+json" in raw,
                     has_math=bool(re.search(r'class="math\b', raw)))
    res.offsite_scripts = [s for s in re.findall(r'<script[^>]*\ssrc="([^"]+)"', raw)
                           if re.match(r"(https?:)?//", s)]
    dom = _chromium(browser, f"{base}/{page}", "--dump-dom")
    res.math = dom.count("<mjx-container")
    res.tex_left = len(re.findall(r'class="math[^"]*">\s*\\[\[(]', dom))
    res.widgets = len(re.findall(r'class="[^"]*\bjupyter-widgets\b', dom))
    res.widget_errors = dom.count("Error rendering Jupyter widget")
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        res.screenshot = out / (page.replace("/", "_").removesuffix(".html") + ".png")
        _chromium(browser, f"{base}/{page}", f"--screenshot={res.screenshot}", "--window-size=1280,5200")
    return res


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):      # keep the report readable
        pass


def serve(folder: Path):
    """A loopback HTTP server for ``folder`` on a free port; returns (server, base URL)."""
    handler = functools.partial(_Quiet, directory=str(folder))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}"


def check(pages=None, use_file: bool = False, out: Path | None = None,
          html: Path = HTML) -> list[PageResult]:
    """Inspect ``pages`` (default: every page of _toc.yml) of the built book in ``html`` (default
    _build/html); see the module doc."""
    pages = toc_pages() if pages is None else list(pages)
    browser = find_browser()
    if browser is None:
        raise FileNotFoundError("no chromium found; install it with `apt-get install -y chromium`")
    missing = [p for p in pages if not (html / p).is_file()]
    if missing:
        raise FileNotFoundError(f"not built: {', '.join(missing)}; run `make book` first")
    if use_file:
        return [inspect(browser, html.as_uri(), p, out, html) for p in pages]
    server, base = serve(html)
    try:
        return [inspect(browser, base, p, out, html) for p in pages]
    finally:
        server.shutdown()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pages", nargs="*", help="pages relative to _build/html (default: every page of _toc.yml)")
    ap.add_argument("--file", action="store_true", help="open pages via file:// instead of a loopback server")
    ap.add_argument("--html", type=Path, default=HTML, help="the built book (default _build/html)")
    ap.add_argument("--out", type=Path, default=ROOT / "_build" / "offline-check", help="screenshot folder")
    args = ap.parse_args(argv)
    try:
        results = check(args.pages or None, args.file, args.out, args.html)
    except FileNotFoundError as err:
        print(f"check_offline: {err}", file=sys.stderr)
        return 3
    failed = 0
    for r in results:
        verdict = "FAIL: " + "; ".join(r.problems) if r.problems else "ok"
        print(f"{r.page}: {r.math} formulas typeset, {r.widgets} widget views "
              f"({'stores' if r.stores_widgets else 'no'} widget state); screenshot {r.screenshot} -> {verdict}")
        failed += bool(r.problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
