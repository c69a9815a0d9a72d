"""`gdlearn render --integrator vpm|bre` with their options, and `gdlearn compare` with both, in
subprocesses (the options travel through argparse, the option table and the integrator)."""
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOG = os.path.join(ROOT, "scenes", "fog-box.xml")


def _cli(command, *args):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "gdlearn", command, *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=900, env=env)


def test_vpm_options_reach_the_integrator(tmp_path):
    r = _cli("render", FOG, "--integrator", "vpm", "--samples", "2", "--volume-radius", "0.1", "--photons", "4000",
             "--spp", "4", "--set", "res=8", "--out", str(tmp_path / "a.npy"), "--buffers", str(tmp_path / "b"),
             "--no-progress")
    assert r.returncode == 0, r.stderr
    img = np.load(tmp_path / "a.npy")
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.mean() > 0
    # two passes: each pixel's R^3 shrank from 0.1^3 by (N + a M) / (N + M) <= 1, somewhere strictly
    rv = np.load(tmp_path / "b" / "volume_radius.npy")
    assert rv.shape == (8, 8) and rv.max() <= 0.1 + 1e-15 and rv.min() < 0.1


def test_bre_media_transport_has_no_surface_light(tmp_path):
    """--transport media keeps only light transport ending in the medium: no emission (the light
    seen directly is surface transport), and still a positive in-scattered image."""
    r = _cli("render", FOG, "--integrator", "bre", "--kernel", "2d", "--radii", "variable", "--neighbors", "16",
             "--transport", "media", "--photons", "4000", "--spp", "4", "--set", "res=8",
             "--out", str(tmp_path / "a.npy"), "--buffers", str(tmp_path / "b"), "--no-progress")
    assert r.returncode == 0, r.stderr
    img = np.load(tmp_path / "a.npy")
    assert np.isfinite(img).all() and img.min() >= 0 and img.mean() > 0
    assert np.all(np.load(tmp_path / "b" / "emission.npy") == 0)


def test_options_are_refused_where_they_do_not_apply(tmp_path):
    out = str(tmp_path / "a.npy")
    for integrator, flag, value in (("vpm", "--kernel", "2d"), ("bre", "--samples", "4"),
                                    ("sppm", "--transport", "media"), ("pt", "--volume-radius", "0.1")):
        r = _cli("render", FOG, "--integrator", integrator, flag, value, "--set", "res=8", "--out", out)
        assert r.returncode == 2 and flag in r.stderr and integrator in r.stderr, (integrator, flag, r.stderr)
    r = _cli("render", FOG, "--integrator", "bre", "--neighbors", "0", "--set", "res=8", "--out", out)
    assert r.returncode == 2 and "neighbors=0" in r.stderr
    r = _cli("render", FOG, "--integrator", "vpm", "--radii", "variable", "--set", "res=8", "--out", out)
    assert r.returncode == 2 and "vpm takes fixed" in r.stderr and "knn" in r.stderr


def test_a_scene_without_media_is_refused_naming_sppm(tmp_path):
    r = _cli("render", os.path.join(ROOT, "scenes", "cornell-box.xml"), "--integrator", "bre", "--set", "res=8",
             "--out", str(tmp_path / "a.npy"), "--no-progress")
    assert r.returncode == 2 and "no participating medium" in r.stderr and "sppm" in r.stderr


def test_compare_accepts_vpm_and_bre_with_options(tmp_path):
    ref = tmp_path / "ref.npy"
    assert _cli("render", FOG, "--integrator", "pt", "--spp", "64", "--set", "res=8", "--out", str(ref),
                "--no-progress").returncode == 0
    r = _cli("compare", FOG, "--methods", "vpm:photons_per_pass=4000,bre:kernel=2d:photons_per_pass=4000",
             "--passes", "2", "-D", "res=8", "--reference", str(ref), "--snapshots", "2", "--executor", "serial")
    assert r.returncode == 0, r.stderr
    rows = {line.split()[0]: line.split() for line in r.stdout.splitlines()[1:]}
    assert set(rows) == {"vpm:photons_per_pass=4000", "bre:kernel=2d:photons_per_pass=4000"}, r.stdout
    assert all(np.isfinite(float(v[1])) and float(v[1]) > 0 for v in rows.values())     # relMSE


def test_volume_radius_scale_reaches_the_integrator(tmp_path):
    """--volume-radius-scale S renders what make(..., volume_radius_scale=S) renders."""
    import gdlearn.scene
    from gdlearn.integrators import make, render

    out = tmp_path / "a.npy"
    r = _cli("render", FOG, "--integrator", "gvpm", "--volume-radius-scale", "0.5", "--transport", "media",
             "--photons", "2000", "--spp", "4", "--seed", "7", "--set", "res=8", "--out", str(out), "--no-progress")
    assert r.returncode == 0, r.stderr
    sc = gdlearn.scene.load(FOG, res=8)
    want = render(make("gvpm", sc, seed=7, volume_radius_scale=0.5, transport="media", photons_per_pass=2000), spp=4)
    other = render(make("gvpm", sc, seed=7, transport="media", photons_per_pass=2000), spp=4)
    got = np.load(out)
    np.testing.assert_array_equal(got, want.primal.astype(got.dtype))
    assert not np.array_equal(got, other.primal.astype(got.dtype))     # the default (0.2) renders another image
