"""`gdlearn render --integrator gpm --recon ...` with its buffers, `gdlearn compare` with gpm+l1, and
the reconstructions leaving the camera-seen emission out (subprocesses: argparse, the option
table, the integrator and the solvers end to end)."""
import os
import subprocess
import sys

import numpy as np

from gdlearn.experiments.solvers import final_image
from gdlearn.integrators import make
from gdlearn.integrators.base import render
from gdlearn.reconstruct import poisson_l2
from gdlearn.scene.load import load

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(ROOT, "scenes", "cornell-box.xml")


def _cli(command, *args):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "gdlearn", command, *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=900, env=env)


def test_render_gpm_with_recon_and_buffers(tmp_path):
    r = _cli("render", CORNELL, "--integrator", "gpm", "--recon", "l1", "--photons", "4000", "--alpha", "0.9",
             "--spp", "4", "--set", "res=12", "--out", str(tmp_path / "a.npy"), "--buffers", str(tmp_path / "b"),
             "--no-progress")
    assert r.returncode == 0, r.stderr
    img = np.load(tmp_path / "a.npy")
    assert img.shape == (12, 12, 3) and np.isfinite(img).all() and img.mean() > 0
    b = tmp_path / "b"
    for name in ("primal", "gx", "gy", "primal_a", "primal_b", "gx_var", "recon", "shift_reconnected",
                 "shift_failed", "shift_manifold", "radius"):
        assert (b / f"{name}.npy").is_file(), name
    assert np.load(b / "shift_reconnected.npy").sum() > 0
    assert np.allclose(np.load(b / "recon.npy"), img)


def test_compare_accepts_gpm(tmp_path):
    r = _cli("compare", CORNELL, "--methods", "sppm:photons_per_pass=4000,gpm:photons_per_pass=4000+l1",
             "--passes", "2", "-D", "res=8", "--reference-spp", "16", "--csv", str(tmp_path / "c.csv"))
    assert r.returncode == 0, r.stderr
    assert "gpm:photons_per_pass=4000+l1" in r.stdout


def test_reconstruction_leaves_the_emission_out():
    """The solvers reconstruct primal - emission from the gradients less the emission's and add the
    emission back; without the split an L2 solve smears a light's edge noise over the walls."""
    f = render(make("gpm", load(CORNELL, res=12), seed=2, photons_per_pass=4000), spp=4)
    assert f.images["emission"].max() > 1.0                   # the light is in view
    e = f.images["emission"]
    want = poisson_l2(f.primal - e, f.gx - f.images["emission_gx"], f.gy - f.images["emission_gy"])
    want = getattr(want, "image", want)
    assert np.allclose(final_image(f, "l2"), np.asarray(want) + e)


def test_radius_scale_sets_the_first_radius_in_footprints(tmp_path):
    # alpha = 1 keeps the first radius; the CLI's --radius-scale must reach the integrator, whose
    # radius is then that multiple of the footprint (a dropped option would give gpm's default 0.35)
    r = _cli("render", CORNELL, "--integrator", "gpm", "--photons", "2000", "--alpha", "1", "--radius-scale", "0.5",
             "--spp", "2", "--set", "res=8", "--out", str(tmp_path / "a.npy"), "--buffers", str(tmp_path / "b"),
             "--no-progress")
    assert r.returncode == 0, r.stderr
    footprint = np.sqrt(make("gpm", load(CORNELL, res=8), radius_scale=1.0).initial_radius2())
    assert np.allclose(np.load(tmp_path / "b" / "radius.npy"), 0.5 * footprint, rtol=1e-12)
