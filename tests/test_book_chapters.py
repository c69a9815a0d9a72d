"""Every chapter of the book executes, in quick mode, without an error (the README's test command
runs this; CI therefore executes the whole book). Collection: tests/conftest.py.

When the quick-mode book build ran earlier in the same session (tests/test_book_build.py), each
chapter's executed notebook is taken from that build's jupyter cache instead of being run again:
the same code in the same quick mode, executed once per session. Otherwise the chapter runs here."""
import pytest

from conftest import executed_by_book_build, execute_chapter


@pytest.mark.notebook
@pytest.mark.timeout(900)
def test_chapter_executes_in_quick_mode(chapter, record_property, quick_book_cache):
    nb = executed_by_book_build(chapter, quick_book_cache)
    if nb is None:
        nb, seconds = execute_chapter(chapter, quick=True)
        record_property("seconds", round(seconds, 1))
        print(f"{chapter.name}: executed in {seconds:.1f} s (quick mode)")
    else:
        print(f"{chapter.name}: outputs of this session's quick-mode book build")
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, f"{chapter.name}: a cell raised {errors[0].get('ename')}: {errors[0].get('evalue')}"
