"""gdlearn: gradient-domain rendering, the package behind the gdlearn book.

The road a scene travels::

    scene.load -> scene.effects -> scene.compile -> integrators.<name> -> reconstruct.<solver>
    -> experiments
"""
import hashlib
import os
import sys
import time
from pathlib import Path

__version__ = "0.1.0"


def source_hash() -> str:
    """A hash of gdlearn's own source files (and the Python version): any edit changes it.

    Caches whose contents depend on gdlearn's code -- numba's compiled kernels, reference images
    rendered by gdlearn -- are keyed by it, so an edit never reuses a stale result."""
    global _SOURCE_HASH
    if _SOURCE_HASH is None:
        root = Path(__file__).resolve().parent
        h = hashlib.sha1(sys.version.encode())
        for p in sorted(root.rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
        _SOURCE_HASH = h.hexdigest()[:16]
    return _SOURCE_HASH


_SOURCE_HASH = None


def _use_source_keyed_numba_cache() -> None:
    """Point numba's on-disk cache at a folder named by a hash of gdlearn's sources.

    Numba re-validates a cached kernel only against the timestamp of the file that *defines* it, not
    of the files whose functions it inlines or calls: after an edit of ``kernels/bsdf/dispatch.py`` a cached
    path tracer would silently keep the old BSDF. Keying the whole cache by the package's source makes
    any edit start from a clean cache. ``NUMBA_CACHE_DIR`` set by the user wins.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    base = Path(os.environ.get("GDLEARN_CACHE", Path.home() / ".cache" / "gdlearn")) / "numba"
    folder = base / source_hash()
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:        # numba read its config already: tell it too
        from numba.core import config
        config.CACHE_DIR = str(folder)
    _prune_old_caches(base, keep=folder)


def _prune_old_caches(base: Path, keep: Path, max_age_days: float = 7.0) -> None:
    """Remove cache folders of older sources unused for a week (they are never valid again)."""
    import shutil

    if not base.is_dir():
        return
    cutoff = time.time() - max_age_days * 86400
    for d in base.iterdir():
        try:
            if d != keep and d.is_dir() and d.stat().st_mtime < cutoff:
                shutil.rmtree(d, ignore_errors=True)
        except OSError:
            pass


def _lock_numba_cache_saves() -> None:
    """Make numba's on-disk cache safe for processes that compile the same function at once (the
    test suite's two pytest-xdist workers, a chapter's kernel beside them, dask workers).

    numba 0.68's ``IndexDataCacheFile.save`` reads the function's index, picks the first free data
    file name, writes the index, then the data, with no lock: two processes saving two signatures of
    one function both pick ``f.1.nbc``, and the index can end up naming the other signature's
    machine code under this one's key. Here a save holds an exclusive ``flock`` on the cache
    folder's lock file while it does the same, and writes the data before the index, so a reader
    that finds a key in the index finds its data whole (each file is replaced atomically, as numba
    does). Without ``fcntl`` (Windows) numba's own save stays.
    """
    try:
        import fcntl
    except ImportError:
        return
    import itertools

    from numba.core import caching

    if getattr(caching.IndexDataCacheFile.save, "_gdlearn_locked", False):
        return
    # written against numba 0.68 (pyproject pins it); another version keeps its own save
    if not all(hasattr(caching.IndexDataCacheFile, m) for m in ("_load_index", "_save_index", "_save_data",
                                                                  "_data_name")):
        return

    def save(self, key, data):
        os.makedirs(self._cache_path, exist_ok=True)
        with open(os.path.join(self._cache_path, ".gdlearn-save.lock"), "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)           # released when the file closes
            overloads = self._load_index()
            name = overloads.get(key)
            if name is None:
                taken = set(overloads.values())
                name = next(n for n in map(self._data_name, itertools.count(1)) if n not in taken)
            self._save_data(name, data)
            if overloads.get(key) != name:
                overloads[key] = name
                self._save_index(overloads)

    save._gdlearn_locked = True
    caching.IndexDataCacheFile.save = save


_use_source_keyed_numba_cache()
_lock_numba_cache_saves()
