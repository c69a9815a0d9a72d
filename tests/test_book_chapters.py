"""Every chapter of the book executes, in quick mode, without an error (the README's test command
runs this; CI therefore executes the whole book). Collection: tests/conftest.py."""
import pytest

from conftest import execute_chapter


@pytest.mark.notebook
@pytest.mark.timeout(900)
def test_chapter_executes_in_quick_mode(chapter, record_property):
    nb, seconds = execute_chapter(chapter, quick=True)
    record_property("seconds", round(seconds, 1))
    print(f"{chapter.name}: executed in {seconds:.1f} s (quick mode)")
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, f"{chapter.name}: a cell raised {errors[0].get('ename')}: {errors[0].get('evalue')}"
