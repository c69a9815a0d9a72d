"""The bad-scene corpus: every file in tests/bad_scenes/ must stop the loader with ONE SceneError
that names the file, the right line, says what is wrong and how to fix it -- never a traceback of
another exception type. The first line of each file is ``<!-- expect line N: fragment -->``: N and
the fragment were written by hand from the file, independent of the loader."""
from __future__ import annotations

import glob
import os
import re

import pytest

from gdlearn.scene.load import load
from gdlearn.scene.model import SceneError

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bad_scenes")
BAD = sorted(glob.glob(os.path.join(HERE, "*.xml")))
EXPECT = re.compile(r"<!-- expect line (\d+): (.*) -->")


def test_corpus_is_large_enough():
    assert len(BAD) >= 30


@pytest.mark.parametrize("path", BAD, ids=os.path.basename)
def test_bad_scene(path):
    with open(path) as fh:
        m = EXPECT.match(fh.readline())
    assert m, f"{path}: first line must be <!-- expect line N: fragment -->"
    line, fragment = int(m.group(1)), m.group(2)
    with pytest.raises(SceneError) as info:
        load(path)
    err = info.value
    assert err.file == path
    assert err.line == line, str(err)
    assert fragment in err.message, str(err)
    assert err.fix and len(err.fix) > 10
    assert str(err).startswith(f"{path}:{line}: ") and "\n  fix: " in str(err)


def test_missing_scene_file(tmp_path):
    path = str(tmp_path / "nope.xml")
    with pytest.raises(SceneError) as info:
        load(path)
    assert info.value.file == path and "cannot read" in info.value.message


def test_override_cannot_hide_a_bad_value():
    # the shipped furnace scene takes rho as a parameter; a bad override is reported at its use site
    path = os.path.join(os.path.dirname(HERE), "..", "scenes", "test", "single-scatter.xml")
    with pytest.raises(SceneError) as info:
        load(path, g=1.0)
    assert "outside (-1, 1)" in info.value.message and info.value.line is not None


def test_mutated_scene_never_raises_anything_but_scene_error(tmp_path):
    """Delete each line of a shipped scene in turn, or garble its numbers: the loader either loads
    or raises SceneError -- no other exception type (a traceback) may escape."""
    src = open(os.path.join(os.path.dirname(HERE), "..", "scenes", "mesh.xml")).read().splitlines()
    meshes = os.path.abspath(os.path.join(os.path.dirname(HERE), "..", "scenes", "meshes"))
    src = [l.replace('value="meshes/', f'value="{meshes}/') for l in src]
    variants = [src[:i] + src[i + 1:] for i in range(len(src))]
    variants += [src[:i] + [src[i].replace('"0', '"x0').replace("1", "-")] + src[i + 1:] for i in range(len(src))]
    outcomes = {"ok": 0, "error": 0}
    for k, lines in enumerate(variants):
        p = tmp_path / f"v{k}.xml"
        p.write_text("\n".join(lines))
        try:
            load(str(p))
            outcomes["ok"] += 1
        except SceneError as err:
            assert err.file == str(p) and err.fix
            outcomes["error"] += 1
    assert outcomes["error"] > 20 and outcomes["ok"] > 20     # both paths were exercised
