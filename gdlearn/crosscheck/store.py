"""Cached Mitsuba 3 reference images: which cases exist, how they are stored, when they are stale.

A reference file ``tests/references/<case>.npz`` holds

* ``mean``   (H x W x 3 float32): Mitsuba's mean image over K independent seeds;
* ``stderr`` (H x W x 3 float32): its per-pixel standard error (sample std over seeds / sqrt(K));
* ``settings`` (a JSON string): scene path, Mitsuba ``<default>`` overrides, resolution, spp per
  seed, the seeds, the variant, Mitsuba's version, and ``scene_sha256``, a hash of the scene file
  *and every file it names* (meshes), so a test can tell that the scene changed after the
  reference was made.

``scripts/make_references.py`` writes them; ``tests/test_mitsuba_crosscheck.py`` reads them.
"""
from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gdlearn.crosscheck.compare import ImageStats

#: Repository root (this file is gdlearn/crosscheck/store.py).
ROOT = Path(__file__).resolve().parents[2]
REF_DIR = ROOT / "tests" / "references"
#: Resolution every reference is rendered at: small enough that a cross-check costs seconds.
RES = 32
REGENERATE = "run: .venv/bin/python scripts/make_references.py"


@dataclass(frozen=True)
class RefCase:
    """One comparison: ``scene`` (path relative to the repository root) rendered by Mitsuba with the
    ``<default>`` overrides ``mitsuba`` (``res`` is always :data:`RES`), and by gdlearn restricted to
    ``effects`` (``None``: everything the scene asks for)."""
    name: str
    scene: str
    mitsuba: dict = field(default_factory=dict, hash=False)
    effects: tuple | None = None

    @property
    def file(self) -> Path:
        return REF_DIR / f"{self.name}.npz"


def shipped_scenes(root: Path = ROOT) -> list[str]:
    """``scenes/*.xml`` and ``scenes/test/*.xml``, relative to ``root``, sorted."""
    found = sorted(root.glob("scenes/*.xml")) + sorted(root.glob("scenes/test/*.xml"))
    return [p.relative_to(root).as_posix() for p in found]


def reference_cases(root: Path = ROOT) -> list[RefCase]:
    """Every shipped scene with its own settings, plus the direct-only cases: ``--effects direct`` on
    the Cornell box and ``direct,single-scattering`` on the fog box and on the medium cube (a bounded medium lit from
    outside), which must equal Mitsuba's
    ``max_depth = 2`` (emitters seen directly + one bounce of direct lighting, where a medium
    scattering vertex counts as a bounce in ``volpath``)."""
    cases = []
    for rel in shipped_scenes(root):
        stem = Path(rel).stem
        name = stem if Path(rel).parent.name == "scenes" else f"test-{stem}"
        cases.append(RefCase(name, rel))
        if stem == "cornell-box":
            cases.append(RefCase(f"{stem}.direct", rel, {"max_depth": 2}, ("direct",)))
        if stem in ("fog-box", "medium-cube"):
            cases.append(RefCase(f"{stem}.direct", rel, {"max_depth": 2},
                                 ("direct", "single-scattering")))
    return cases


_FILENAME = re.compile(r'name\s*=\s*"filename"\s+value\s*=\s*"([^"$]+)"')


def scene_sha256(path) -> str:
    """SHA-256 of the scene file's bytes followed by those of every file it names (``filename``
    strings, e.g. meshes, relative to the scene's folder)."""
    path = Path(path)
    h = hashlib.sha256(path.read_bytes())
    for name in _FILENAME.findall(path.read_text(errors="replace")):
        f = (path.parent / name)
        h.update(name.encode())
        h.update(f.read_bytes() if f.is_file() else b"<missing>")
    return h.hexdigest()


def save_reference(case: RefCase, mean, stderr, settings: dict, root: Path = ROOT) -> Path:
    """Write ``case``'s reference file (float32 arrays, settings as JSON incl. the scene hash)."""
    settings = dict(settings, scene=case.scene, name=case.name, mitsuba_defaults=case.mitsuba,
                    effects=list(case.effects) if case.effects else None,
                    scene_sha256=scene_sha256(root / case.scene))
    case.file.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(case.file, mean=np.asarray(mean, np.float32),
                        stderr=np.asarray(stderr, np.float32), settings=np.array(json.dumps(settings)))
    return case.file


def load_reference(case: RefCase, root: Path = ROOT) -> tuple[ImageStats, dict]:
    """The stored reference of ``case`` as :class:`ImageStats` and its settings. Raises
    FileNotFoundError / ValueError (stale: the scene changed) with the command that fixes it."""
    if not case.file.is_file():
        raise FileNotFoundError(f"no Mitsuba reference for {case.name} ({case.file}); {REGENERATE}")
    with np.load(case.file, allow_pickle=False) as z:
        mean, se, settings = z["mean"], z["stderr"], json.loads(str(z["settings"]))
    now = scene_sha256(root / case.scene)
    if settings.get("scene_sha256") != now or settings.get("mitsuba_defaults") != case.mitsuba:
        raise ValueError(f"Mitsuba reference {case.file.name} is stale: {case.scene} (or a file it "
                         f"names, or the case's settings) changed since it was made; {REGENERATE}")
    return ImageStats.from_mean_stderr(mean, se, len(settings["seeds"])), settings
