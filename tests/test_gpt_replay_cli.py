"""`gdlearn render --integrator gpt-replay --recon ...` end to end, in subprocesses: the buffers follow
the reconstruction library's conventions and --out holds the reconstruction of exactly those buffers
(recomputed here with gdlearn.reconstruct, independently of the CLI); a primal integrator refuses
--recon with exit status 2."""
import os
import subprocess
import sys

import numpy as np

from gdlearn.io import read_image
from gdlearn.reconstruct import control_variates, poisson_l2

#: Bound on one child process (it may JIT-compile numba kernels cold, which took > 120 s on a busy
#: 2-core machine). It only bounds a hang: subprocess.run kills the child when it expires, and no
#: assertion depends on how long the child took.
SUBPROCESS_TIMEOUT = 1800


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cornell-box.xml")


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "gdlearn", "render", SCENE, "--set", "res=12", "--spp", "4",
                           "--no-progress", *args], cwd=ROOT, capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT)


def test_recon_writes_the_reconstruction_of_the_written_buffers(tmp_path):
    for solver, fn in (("cv", control_variates), ("l2", poisson_l2)):
        out, buf = tmp_path / f"{solver}.npy", tmp_path / f"buf-{solver}"
        r = _cli("--integrator", "gpt-replay", "--recon", solver, "--out", str(out), "--buffers", str(buf))
        assert r.returncode == 0, r.stderr
        names = set(os.listdir(buf))
        assert {"primal.npy", "gx.npy", "gy.npy", "gx_var.npy", "gy_a.npy", "recon.npy"} <= names, names
        p, gx, gy = (np.load(buf / f"{n}.npy") for n in ("primal", "gx", "gy"))
        img = read_image(out)
        np.testing.assert_allclose(img, fn(p, gx, gy).image, rtol=1e-10, atol=1e-12)
        assert not np.array_equal(img, p)          # it is not the primal written under another name
        assert np.all(gx[:, -1] == 0) and np.all(gy[-1] == 0)   # undefined borders, masked by solvers


def test_recon_without_gradients_is_refused(tmp_path):
    r = _cli("--integrator", "pt", "--recon", "cv", "--out", str(tmp_path / "a.npy"))
    assert r.returncode == 2 and "gradient integrator" in r.stderr, r.stderr
