"""The layering of ARCHITECTURE.md holds: import-linter checks the contracts in pyproject.toml.

Kernels import nothing above them, shifts never import integrators, reconstruct imports nothing else
from gdlearn, the book support (``gdlearn.teaching``) imports the pipeline and never the reverse, and
the packages form layers in the order of the road a scene travels. The second test plants a
contract the code breaks and checks that the same command reports it, so the first cannot pass
by checking nothing.
"""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _lint(config: Path) -> subprocess.CompletedProcess:
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail("lint-imports not installed: pip install -e '.[dev]' (import-linter)")
    return subprocess.run([exe, "--no-cache", str(config)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def test_the_layering_contracts_are_kept():
    r = _lint(ROOT / "pyproject.toml")
    assert r.returncode == 0 and "0 broken" in r.stdout, r.stdout + r.stderr


def test_a_planted_violation_is_reported(tmp_path):
    config = (ROOT / "pyproject.toml").read_text()
    config += '''
[[tool.importlinter.contracts]]
name = "planted: integrators may not use the kernels"
type = "forbidden"
source_modules = ["gdlearn.integrators"]
forbidden_modules = ["gdlearn.kernels"]
'''
    cfg = tmp_path / "pyproject.toml"
    cfg.write_text(config)
    r = _lint(cfg)
    assert r.returncode != 0 and "planted: integrators may not use the kernels BROKEN" in r.stdout, r.stdout
