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
