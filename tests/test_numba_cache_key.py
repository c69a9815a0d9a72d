"""Numba's on-disk cache is keyed by a hash of gdlearn's sources (gdlearn/__init__.py).

Numba re-validates a cached kernel only against its own file, so an edit of a callee (a BSDF, say)
would otherwise leave stale machine code running. These tests check that the cache folder follows
the sources: same sources -> same folder, one changed byte in any module -> another folder."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cache_dir(pkg_parent: Path, cache: Path) -> str:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(GDLEARN_CACHE=str(cache), PYTHONPATH=str(pkg_parent))
    code = "import os, gdlearn; print(os.environ['NUMBA_CACHE_DIR']); print(gdlearn.source_hash())"
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=str(pkg_parent), capture_output=True,
                         text=True, check=True, timeout=120).stdout.split()
    assert out[0] == str(cache / "numba" / out[1])
    return out[0]


def test_cache_folder_follows_the_sources(tmp_path):
    copy = tmp_path / "src"
    shutil.copytree(ROOT / "gdlearn", copy / "gdlearn", ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "cache"
    first = _cache_dir(copy, cache)
    assert _cache_dir(copy, cache) == first                      # deterministic
    bsdf = copy / "gdlearn" / "kernels" / "bsdf" / "dispatch.py"
    bsdf.write_text(bsdf.read_text() + "\n# an edit of a callee only\n")
    assert _cache_dir(copy, cache) != first                      # any edit: a fresh cache


def test_user_setting_wins(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "mine"), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", "import os, gdlearn; print(os.environ['NUMBA_CACHE_DIR'])"],
                         env=env, capture_output=True, text=True, check=True, timeout=120).stdout.strip()
    assert out == str(tmp_path / "mine")


#: A process that saves one signature of a function into a shared numba cache folder, after waiting
#: until every other such process is ready; its index read is slowed down to widen the window
#: between reading the index and writing it, where two unguarded saves race.
_SAVER = """
import sys, time
from pathlib import Path
import gdlearn  # noqa: F401  (installs the locked save)
from numba.core import caching

class SlowIndex(caching.IndexDataCacheFile):
    def _load_index(self):
        overloads = super()._load_index()
        time.sleep(0.3)
        return overloads

folder, key, n = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
(folder / f"ready-{key}").touch()
while len(list(folder.glob("ready-*"))) < n:
    time.sleep(0.005)
SlowIndex(str(folder / "cache"), "kernel", ("stamp", 1)).save(key, ("machine code of", key))
"""


def test_concurrent_saves_of_one_function_keep_every_signature(tmp_path):
    """Processes compiling the same function at once (pytest-xdist workers, a chapter's kernel) save
    different signatures into one index: each key must still load its own data (gdlearn's locked
    save; numba's own lets them all pick the same data file and keeps one key)."""
    from numba.core import caching

    keys = [f"sig-{i}" for i in range(3)]
    (tmp_path / "cache").mkdir()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    procs = [subprocess.Popen([sys.executable, "-c", _SAVER, str(tmp_path), k, str(len(keys))], env=env)
             for k in keys]
    assert [p.wait(timeout=300) for p in procs] == [0] * len(keys)
    index = caching.IndexDataCacheFile(str(tmp_path / "cache"), "kernel", ("stamp", 1))
    assert {k: index.load(k) for k in keys} == {k: ("machine code of", k) for k in keys}
