"""Cached references: keys follow scene content, the cache is reused, files load back."""
import numpy as np
import pytest

from gdlearn.experiments import references as R
from gdlearn.teaching.toy import ToyScene


def test_key_follows_scene_content(tmp_path):
    (tmp_path / "m.obj").write_text("v 0 0 0\n")
    scene = tmp_path / "s.xml"
    scene.write_text('<scene><shape type="obj"><string name="filename" value="x"/></shape>'
                     '<shape type="obj" filename="m.obj"/></scene>')
    k1 = R.cache_key(scene, "pt", 64, 1)
    assert R.cache_key(scene, "pt", 64, 1) == k1
    assert R.cache_key(scene, "pt", 128, 1) != k1 and R.cache_key(scene, "gpt", 64, 1) != k1
    (tmp_path / "m.obj").write_text("v 0 0 1\n")       # a referenced mesh changed
    assert R.cache_key(scene, "pt", 64, 1) != k1


def test_key_of_named_sources_only(tmp_path):
    scene = tmp_path / "s.xml"
    scene.write_text("<scene/>")
    whole = R.cache_key(scene, "pt", 64, 1)
    pt_only = R.cache_key(scene, "pt", 64, 1, ("kernels", "integrators/path/pt.py"))
    assert pt_only != whole and pt_only == R.cache_key(scene, "pt", 64, 1, ("integrators/path/pt.py", "kernels"))
    assert R.source_digest(("kernels",)) != R.source_digest(("kernels/rng.py",))
    with pytest.raises(FileNotFoundError, match="relative to the package"):
        R.source_digest(("gdlearn/kernels",))


def test_render_reference_is_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("GDLEARN_CACHE", str(tmp_path))
    sc = ToyScene(10, 6)
    est = "gdlearn.teaching.toy:ToyPrimal"
    a = R.render_reference(sc, est, spp=64, spp_per_pass=8)
    assert a.spp == 64 and a.variance is not None and np.isfinite(a.floor) and a.floor > 0
    files = list((tmp_path / "references").glob("*.npz"))
    assert len(files) == 1
    b = R.render_reference(sc, est, spp=64, spp_per_pass=8)
    assert b.path == files[0]
    np.testing.assert_array_equal(a.image, b.image)
    assert b.floor == pytest.approx(a.floor)
    # the reference judges the estimate with error ~ its floor: more spp, lower floor (~1/spp)
    c = R.render_reference(sc, est, spp=256, spp_per_pass=8)
    assert c.floor < a.floor


def test_a_one_pass_budget_still_has_a_noise_estimate(tmp_path, monkeypatch):
    # spp_per_pass >= spp would render one pass, whose two halves are the same estimate (variance 0):
    # the floor would read 0, a noisy reference reported as perfect
    monkeypatch.setenv("GDLEARN_CACHE", str(tmp_path))
    est = "gdlearn.teaching.toy:ToyPrimal"
    a = R.render_reference(ToyScene(10, 6), est, spp=16, spp_per_pass=64)
    assert a.spp == 16 and np.isfinite(a.floor) and a.floor > 0
    one = R.render_reference(ToyScene(10, 6), est, spp=1, spp_per_pass=64)
    assert np.isnan(one.floor)                         # one sample: no noise estimate at all


def test_load_reference_formats(tmp_path):
    img = np.arange(24, dtype=float).reshape(2, 4, 3)
    np.save(tmp_path / "r.npy", img)
    r = R.load_reference(tmp_path / "r.npy")
    np.testing.assert_array_equal(r.image, img)
    assert np.isnan(r.floor)                           # unknown noise: no floor drawn
    with pytest.raises(FileNotFoundError, match="does not exist"):
        R.load_reference(tmp_path / "missing.exr")
    with pytest.raises(ValueError, match="npz"):
        (tmp_path / "r.png").write_bytes(b"x")
        R.load_reference(tmp_path / "r.png")


@pytest.mark.mitsuba
def test_mitsuba_reference_has_noise_estimate(tmp_path, monkeypatch):
    pytest.importorskip("mitsuba")
    from pathlib import Path
    from gdlearn.experiments.study import SceneFile

    monkeypatch.setenv("GDLEARN_CACHE", str(tmp_path))
    scene = SceneFile(str(Path(__file__).parent.parent / "scenes" / "cornell-box.xml"), (("res", 8),))
    ref = R.mitsuba_reference(scene, spp=64, seeds=(1, 2))
    assert ref.image.shape == (8, 8, 3) and np.isfinite(ref.image).all()
    assert ref.variance.shape == ref.image.shape and 0 < ref.floor < np.inf
    again = R.mitsuba_reference(scene, spp=64, seeds=(1, 2))       # from the cache
    assert again.path is not None
    np.testing.assert_array_equal(again.image, ref.image)


def test_concurrent_saves_of_one_reference(tmp_path, monkeypatch):
    """Two processes saving the same reference at once (pytest-xdist workers, a chapter's kernel):
    here the second save runs whole while the first has written its temporary file but not yet
    moved it into place. Both succeed, the file loads back, and no temporary file is left."""
    path = tmp_path / "references" / "k.npz"
    first, second = R.Reference(np.zeros((2, 2, 3)), spp=1), R.Reference(np.ones((2, 2, 3)), spp=2)
    savez, calls = np.savez_compressed, []

    def savez_then_interleave(file, **arrays):
        savez(file, **arrays)
        calls.append(file)
        if len(calls) == 1:                             # the first save is between write and move
            second.save(path)

    monkeypatch.setattr(np, "savez_compressed", savez_then_interleave)
    first.save(path)
    assert R.load_reference(path).spp == 1              # the last move wins, whole
    assert [p.name for p in path.parent.iterdir()] == ["k.npz"]
