"""`gdlearn render --integrator sppm --photons N --alpha A --radius R`, in a subprocess."""
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cornell-box.xml")


def _cli(*args):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "gdlearn", "render", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, env=env)


def test_sppm_options_reach_the_integrator(tmp_path):
    r = _cli(SCENE, "--integrator", "sppm", "--photons", "4000", "--alpha", "0.8", "--radius", "0.05",
             "--spp", "4", "--set", "res=8", "--out", str(tmp_path / "a.npy"), "--buffers", str(tmp_path / "b"),
             "--no-progress")
    assert r.returncode == 0, r.stderr
    img = np.load(tmp_path / "a.npy")
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.mean() > 0
    # two passes (2 camera samples each): R^2 shrank from 0.05^2 by (N + a M) / (N + M) <= 1
    rad = np.load(tmp_path / "b" / "radius.npy")
    assert rad.max() <= 0.05 + 1e-15 and rad.min() < 0.05
    # the photon-count map N and the exactly-added emission are buffers too; N = alpha x photons found
    # in the first pass + alpha x the second's, so it is >= 0 and somewhere > 0 (4000 photons, 8 x 8)
    n = np.load(tmp_path / "b" / "photon_count.npy")
    assert n.shape == (8, 8) and n.min() >= 0 and n.max() > 0
    em = np.load(tmp_path / "b" / "emission.npy")
    assert em.shape == (8, 8, 3) and np.all(em <= img + 1e-12)     # emission is a part of the primal


def test_photon_options_are_refused_for_other_integrators(tmp_path):
    r = _cli(SCENE, "--photons", "10", "--set", "res=8", "--out", str(tmp_path / "a.npy"))
    assert r.returncode == 2 and "--photons" in r.stderr


def test_direct_option_reaches_the_integrator(tmp_path):
    """--direct nee changes which estimator gives the direct light: with the same seed and photons,
    the images differ (the photon-only image is what --direct photons gives bit for bit)."""
    imgs = {}
    for direct in ("photons", "nee"):
        out = tmp_path / f"{direct}.npy"
        r = _cli(SCENE, "--integrator", "sppm", "--photons", "4000", "--direct", direct, "--spp", "2",
                 "--set", "res=8", "--out", str(out), "--no-progress")
        assert r.returncode == 0, r.stderr
        imgs[direct] = np.load(out)
    base = tmp_path / "default.npy"
    assert _cli(SCENE, "--integrator", "sppm", "--photons", "4000", "--spp", "2", "--set", "res=8", "--out",
                str(base), "--no-progress").returncode == 0
    assert np.array_equal(np.load(base), imgs["photons"])
    assert np.isfinite(imgs["nee"]).all() and not np.array_equal(imgs["nee"], imgs["photons"])
