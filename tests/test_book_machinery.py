"""The book's helpers: quick-mode budgets, the widgets' content and offline wiring, the build
script's cache fingerprint."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from gdlearn.teaching import quick, widgets

ROOT = Path(__file__).resolve().parent.parent


# -- quick mode ------------------------------------------------------------------------------------
def test_budget_follows_the_environment(monkeypatch):
    monkeypatch.delenv("GDLEARN_QUICK", raising=False)
    assert quick.budget(full=256, quick=8) == 256 and not quick.is_quick()
    monkeypatch.setenv("GDLEARN_QUICK", "1")
    assert quick.budget(full=256, quick=8) == 8 and quick.is_quick()
    monkeypatch.setenv("GDLEARN_QUICK", "0")
    assert quick.budget(full=2.0, quick=0.5) == 2.0


def test_budget_rejects_a_quick_budget_above_the_full_one():
    with pytest.raises(ValueError, match="exceeds the full budget"):
        quick.budget(full=8, quick=256)


def test_captions_say_the_budget_and_quick_mode(monkeypatch):
    monkeypatch.delenv("GDLEARN_QUICK", raising=False)
    assert quick.caption("Cornell box", spp=16, seed=1) == "Cornell box (16 spp, seed 1)"
    assert quick.describe(seconds=2, res=64) == "2.0 s, 64x64 px"
    monkeypatch.setenv("GDLEARN_QUICK", "yes")
    assert quick.caption("Cornell box", spp=4, seed=1) == "Cornell box (4 spp, seed 1, quick mode)"


# -- widgets ---------------------------------------------------------------------------------------
def test_glued_sentences_show_without_quotes():
    from gdlearn.teaching.quick import Sentence
    # {glue:text} prints the repr: a str would show as 'text' with its quotes
    assert repr(Sentence("replay wins")) == "replay wins"
    assert repr("replay wins") != "replay wins"


def test_srgb_transfer_curve():
    # Values from IEC 61966-2-1 by hand: 0.5 linear -> 1.055 * 0.5^(1/2.4) - 0.055 = 0.7354 -> 188.
    img = np.array([[0.0, 0.5, 1.0, 4.0, np.nan]])
    assert widgets.srgb(img)[0, :, 0].tolist() == [0, 188, 255, 255, 0]
    assert widgets.srgb(np.full((1, 1, 3), 0.25), exposure=1.0)[0, 0, 0] == 188   # 2^1 * 0.25 = 0.5


def _state(view):
    """The stored state of ``view``: its widgets plus the jslinks between them (a notebook stores every
    live widget; here other tests' widgets are alive too, so keep only links touching this view)."""
    from ipywidgets.embed import dependency_state, embed_data

    mine = dependency_state(view)
    everything = embed_data(views=[view])["manager_state"]["state"]
    ids = {f"IPY_MODEL_{k}" for k in mine}
    links = {k: m for k, m in everything.items() if m["model_name"] == "LinkModel"
             and m["state"]["source"][0] in ids and m["state"]["target"][0] in ids}
    return {**mine, **links}


def _links(state):
    return [m for m in state.values() if m["model_name"] == "LinkModel"]


def test_compare_images_reports_relmse_and_stores_browser_links():
    ref = np.full((8, 8, 3), 0.5)
    view = widgets.compare_images({"a": ref * 1.1, "b": ref}, reference=ref)
    state = _state(view)
    # relMSE of a 10 % error at R = 0.5: (0.05^2) / (0.25 + 0.001) = 0.00996..., by hand.
    expected = 0.05 ** 2 / (0.25 + 0.001)
    html = " ".join(m["state"].get("value", "") for m in state.values() if m["model_name"] == "HTMLModel")
    assert f"{expected:.4g}" in html
    stacks = [m for m in state.values() if m["model_name"] == "StackModel"]
    assert len(stacks) == 1 and len(stacks[0]["state"]["children"]) == 3       # a, b, reference
    # Flip buttons and slider are wired in the browser (jslink), so the static page stays live.
    assert len(_links(state)) == 2


def test_parameter_explorer_computes_each_combination_once_and_links_every_stack():
    calls = []

    def picture(a, b):
        calls.append((a, b))
        return np.full((4, 4, 3), a * b)

    view = widgets.parameter_explorer(picture, a=[0.1, 0.2, 0.3], b=[1, 2])
    assert sorted(calls) == sorted((a, b) for a in (0.1, 0.2, 0.3) for b in (1, 2))
    # One link for the outer stack (a) and one per inner stack (b): 1 + 3.
    assert len(_links(_state(view))) == 4


def test_views_refuse_too_many_pictures_and_wrong_shapes():
    with pytest.raises(ValueError, match="MAX_VIEWS"):
        widgets.parameter_explorer(lambda a, b: np.zeros((2, 2, 3)), a=range(10), b=range(10))
    with pytest.raises(ValueError, match="H x W x 3"):
        widgets.progressive_viewer([np.zeros((2, 2, 4))])
    with pytest.raises(ValueError, match="at least one"):
        widgets.compare_images({})


def test_progressive_viewer_labels_frames_with_their_budget():
    from gdlearn.integrators.base import Frame

    img = np.full((4, 4, 3), 0.5)
    frame = Frame(passes=3, spp=12, images={"primal": img}, halves={}, timings={}, stats={}, elapsed=1.5)
    state = _state(widgets.progressive_viewer([frame, img * 2]))
    html = " ".join(m["state"].get("value", "") for m in state.values() if m["model_name"] == "HTMLModel")
    assert "pass 3: 12 spp, 1.50 s" in html and "frame 1" in html
    assert any(m["model_name"] == "PlayModel" for m in state.values())


# -- build script ----------------------------------------------------------------------------------
def _build_book_module():
    spec = importlib.util.spec_from_file_location("build_book", ROOT / "scripts" / "build_book.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cache_is_wiped_when_the_fingerprint_changes(tmp_path, monkeypatch):
    bb = _build_book_module()
    monkeypatch.setattr(bb, "CACHE", tmp_path / ".jupyter_cache")
    monkeypatch.setattr(bb, "STAMP", tmp_path / "fingerprint")
    monkeypatch.setattr(bb, "DOCTREES", tmp_path / ".doctrees")
    assert bb.fingerprint(quick=True) != bb.fingerprint(quick=False)
    bb.CACHE.mkdir()
    assert bb.refresh_cache(quick=False, fresh=False).startswith("cleared")     # no stamp yet
    bb.CACHE.mkdir()
    (bb.CACHE / "kept").write_text("x")
    assert bb.refresh_cache(quick=False, fresh=False).startswith("kept")
    assert (bb.CACHE / "kept").exists()
    bb.DOCTREES.mkdir()
    assert bb.refresh_cache(quick=True, fresh=False).startswith("cleared")      # mode switched
    assert not bb.CACHE.exists() and not bb.DOCTREES.exists()     # no page may keep old outputs
    bb.STAMP.write_text("an old environment\n")
    bb.CACHE.mkdir()
    assert bb.refresh_cache(quick=True, fresh=False).startswith("cleared")
