"""Gradient-domain volumetric photon mapping (Gruson et al. 2018, Sec. 4): the base estimate is VPM's,
the gradients are unbiased at a fixed radius (PHOTONS.md T3) for the mixed and the simple shift,
the shifts succeed often enough to lower the gradients' variance, the MIS weights of a real pair
sum to one (T4), and the refusals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.base import render
from gdlearn.scene.load import load
from conftest import gradient_residuals

#: one fixed radius for every pixel and no reduction (alpha = 1): each pass is an independent estimate
#: of the medium radiance blurred by a ball of radius 0.25, and the gradients must be unbiased for
#: its differences
FIXED = dict(photons_per_pass=8000, volume_radius=0.25, alpha=1.0, transport="media", samples=4)
#: 32 seeds x 16 passes at 12 x 12: a skipped visibility test (offset photons behind a wall or in a
#: box's shadow accepted) is a bias of a few per cent of the gradient near the occluders, which
#: fewer samples do not resolve (mean z^2 1.2-1.4 at 8 passes)
N_SEEDS = 32
SPP = 32


@pytest.fixture(scope="module")
def fog():
    return load("scenes/fog-box.xml", res=12)


def _runs(scene, shift, seeds=N_SEEDS, spp=SPP, **kw):
    """Per seed: (gx - FD(base), gy - FD(base), primal - base, gx, FD_x(base)) channel means."""
    out = []
    for seed in range(seeds):
        f = render(make("gvpm", scene, seed=900 + seed, shift=shift, **{**FIXED, **kw}), spp=spp)
        out.append(gradient_residuals(f))
        last = f
    return np.array(out), last


@pytest.fixture(scope="module")
def runs(fog):
    return _runs(fog, "mixed")


@pytest.fixture(scope="module")
def simple_runs(fog):
    """The simple shift (every photon translated and reconnected), at a quarter of the cost."""
    return _runs(fog, "simple", seeds=24, spp=16, photons_per_pass=4000)


def test_base_estimate_is_vpm(fog):
    """The base buffer is VPM's medium estimate for the same seed and fixed radius (same photons, same
    gather points, same distance samples), to rounding: the order of the sums differs."""
    g = render(make("gvpm", fog, seed=3, **FIXED), spp=4)
    v = render(make("vpm", fog, seed=3, **FIXED), spp=4)
    assert np.allclose(g.images["primal_base"], v.primal, rtol=1e-12, atol=1e-15)
    assert v.primal.mean() > 1e-3


def test_first_volume_radius_is_a_fraction_of_vpms(fog):
    """gvpm and gbre start from their own VOLUME_RADIUS_SCALE x VPM's (and the BRE's) default volume
    radius (gvpm's and gbre's module docstrings: the gradients afford a smaller kernel); an explicit
    volume_radius_scale or volume_radius still wins."""
    from gdlearn.integrators.photon import gbre, gvpm

    opts = dict(photons_per_pass=2000, transport="media")
    vpm = make("vpm", fog, **opts).initial_volume_radius()
    assert vpm > 0
    for name, scale in (("gvpm", gvpm.VOLUME_RADIUS_SCALE), ("gbre", gbre.VOLUME_RADIUS_SCALE)):
        assert 0 < scale < 1
        assert math.isclose(make(name, fog, **opts).initial_volume_radius(), scale * vpm, rel_tol=1e-12)
        assert math.isclose(make(name, fog, volume_radius_scale=1.0, **opts).initial_volume_radius(), vpm,
                            rel_tol=1e-12)
        assert make(name, fog, volume_radius=0.05, **opts).initial_volume_radius() == 0.05
    assert math.isclose(make("bre", fog, **opts).initial_volume_radius(), vpm, rel_tol=1e-12)


def _z(d):
    m = d.mean(0)
    se = d.std(0, ddof=1) / math.sqrt(len(d))
    ok = se > 1e-12
    return m[ok] / se[ok]


@pytest.mark.parametrize("i,name", [(0, "gx"), (1, "gy"), (2, "primal")])
def test_unbiased_at_fixed_radius(runs, i, name):
    """gx - (I[x+1] - I[x]) of the base (and gy, and the MIS primal - the base) has mean zero per
    pixel: the paired difference cancels most photon noise, so this resolves biases far below the
    noise of either image. Over 32 seeds z is Student-t with 31 degrees of freedom: E z^2 = 31/29 =
    1.07; 1.45 leaves room for the heavier tails of a few pixels (as tests/test_gpm.py), and |z| > 5.5
    has probability ~1e-5 per pixel. A skipped visibility test on the reconnection fails gx, a
    factor 1.1 on the reconnected photon's power fails the primal, a dropped MIS weight (w = 1 both
    ways) fails all three (numbers in the commit message that added this test)."""
    d, _ = runs
    _check_z(d[:, i], name)


@pytest.mark.parametrize("i,name", [(0, "gx"), (1, "gy"), (2, "primal")])
def test_simple_shift_unbiased_at_fixed_radius(simple_runs, i, name):
    _check_z(simple_runs[0][:, i], name)


def _check_z(d, name, min_pixels=100):
    z = _z(d)
    assert z.size > min_pixels, "too few pixels with a spread: the shifts or the photons are missing"
    assert (z ** 2).mean() < 1.45, f"{name}: mean z^2 {(z ** 2).mean():.2f} (max |z| {np.abs(z).max():.1f})"
    assert np.abs(z).max() < 5.5, f"{name}: max |z| {np.abs(z).max():.1f}"


def test_shifts_succeed_and_lower_the_variance(runs):
    """Most photon shifts succeed on the fog box (a third or so null, the rest reconnected, some of
    them reflected by Eq. 16), and the gradient is less noisy than the difference of two primal
    estimates. Failing every shift would pass the unbiasedness test trivially; this one would fail."""
    d, last = runs
    im = last.images
    ok = im["shift_null"].sum() + im["shift_reconnected"].sum()
    assert ok > 3 * im["shift_failed"].sum()
    assert im["shift_null"].sum() > 0.1 * ok and im["shift_mixed"].sum() > 0.1 * im["shift_reconnected"].sum()
    interior = (slice(None), slice(1, -1), slice(1, -2))
    ratio = d[:, 3][interior].var(axis=0).mean() / d[:, 4][interior].var(axis=0).mean()
    assert ratio < 0.5, f"var(gx) / var(FD of the primal) = {ratio:.2f}"


@pytest.fixture(scope="module")
def spot_runs():
    """scenes/spot-medium.xml: a spot light in vacuum above a block of smoke bounded by a null cube, so
    every single-scattered photon's edge from the light crosses the block's top (a null interface)
    and its reconnection walks through it (gvpm_light.edge_walk)."""
    scene = load("scenes/spot-medium.xml", res=16)
    return _runs(scene, "mixed", seeds=24, spp=16, volume_radius=0.15)


@pytest.mark.parametrize("i,name", [(0, "gx"), (1, "gy"), (2, "primal")])
def test_unbiased_through_null_interfaces(spot_runs, i, name):
    """As test_unbiased_at_fixed_radius (24 seeds: E z^2 = 1.10), and most shifts succeed. Dropping
    the transmittance of the edge's last media segment (after the null crossing) fails it (gy mean
    z^2 15, primal 108); measuring that segment from the light instead of from the block's top does
    not (0.90 / 1.15 / 0.86: under a spot straight above, the vacuum part's length changes only to
    second order); refusing every null crossing would pass it trivially and fails the count."""
    d, last = spot_runs
    _check_z(d[:, i], name, min_pixels=80)      # the block covers ~90 of the 256 pixels
    assert last.images["shift_reconnected"].sum() > 3 * last.images["shift_failed"].sum()


def test_refusals(fog):
    with pytest.raises(ValueError, match="mixed"):
        make("gvpm", fog, transport="media", shift="rotate")
    with pytest.raises(ValueError, match="knn"):
        make("gvpm", fog, transport="media", radii="knn")
    with pytest.raises(ValueError, match="medium"):
        make("gvpm", load("scenes/cornell-box.xml", res=8), transport="media")


def test_mis_weights_of_a_pair_sum_to_one():
    """PHOTONS.md T4 on real light paths of the fog box and real kernel code: a volume photon b moved by
    the mixed shift (gather point d -> d') and reconnected from its parent (the emitter, a wall, a
    medium vertex), and the reverse shift of the offset path (d' -> d: the mixed shift returns b, the
    reconnection from the same parent) give light-side density ratios r, r' with r r' = 1 and
    power ratios that invert; the camera side's ratio (the distance copy between two beams of
    different lengths and weights: each side's own selection probability and truncated density,
    E10) inverts too, so w(x) + w(T x) = 1 to 1e-9. Random gather points within r of the photon,
    |d' - d| up to 1.5 r."""
    from gdlearn.integrators.photon import gvpm_gather as gg
    from gdlearn.integrators.photon.camera_beams import BEAM_COLS, BEAM_D, BEAM_S, BEAM_W, MAX_BEAMS
    from gdlearn.integrators.photon.gvpm_light import OK, reconnect
    from gdlearn.kernels.accel.bvh import STACK_SIZE
    from gdlearn.photons.records import K_MEDIUM
    from gdlearn.shifts.mis import mis_weight_from_log_ratio
    from gdlearn.shifts.volume_photon import NULL, mixed_shift, truncated_distance_pdf

    g = make("gvpm", load("scenes/fog-box.xml", res=8), transport="media", photons_per_pass=100)
    sa = g.setup.sa
    lp = g.tracer.trace(11, 0, 0, 600)
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    rng = np.random.default_rng(8)
    r = 0.3
    # two camera paths of two beams each, different lengths and weights: base and offset
    beams = [np.zeros((MAX_BEAMS, BEAM_COLS)) for _ in range(2)]
    for bm, s, wts in ((beams[0], (1.3, 2.9), (0.9, 0.35)), (beams[1], (1.45, 2.6), (0.8, 0.5))):
        for i in range(2):
            bm[i, BEAM_D + 2] = -1.0
            bm[i, BEAM_S] = s[i]
            bm[i, BEAM_W:BEAM_W + 3] = wts[i]
    tested = {}
    for v in np.flatnonzero((lp.kind == K_MEDIUM) & (lp.parent >= 0)):
        b = lp.pos[v].copy()
        d = b + _ball_point(rng, r)
        d2 = d + _ball_point(rng, 1.5 * r)
        b2, kind = mixed_shift(tuple(b), tuple(d), tuple(d2), r)
        if kind == NULL:
            continue
        st, f3, rl, w_new = reconnect(sa, lp, v, b2, stack)
        if st != OK:
            continue
        lp2 = type(lp)(*(f.copy() for f in lp))      # the offset light path, as if it had been traced
        lp2.pos[v] = b2
        lp2.d_in[v] = w_new
        back, kind2 = mixed_shift(b2, tuple(d2), tuple(d), r)
        assert np.allclose(back, b, rtol=0, atol=1e-12) and kind2 == kind
        st2, f3b, rlb, _ = reconnect(sa, lp2, v, tuple(b), stack)
        assert st2 == OK
        assert rl * rlb == pytest.approx(1.0, abs=1e-9)
        assert np.allclose(np.array(f3) * np.array(f3b), 1.0, rtol=1e-9)
        # the camera side, through the kernel's own code, beam k and a distance t both beams reach
        k, t = int(rng.integers(2)), rng.uniform(0.0, 1.3)
        rc = []
        for i in range(2):
            base, off = beams[i], beams[1 - i]
            pb = gg._beam_prob(base, 2, k)
            pdf = truncated_distance_pdf(0.2, base[k, BEAM_S], t)
            og = np.zeros((4, 12))
            gg._offset_gather((np.stack([off] * 4), np.array([True, False, False, False])), 2, k, t, 0.2, pb,
                              pdf, (1.0, 1.0, 1.0), 1.0, og)
            assert og[0, 0] == 1.0 and og[1, 0] == 0.0
            rc.append(og[0, 10])
        w = mis_weight_from_log_ratio(math.log(rc[0] * rl)) + mis_weight_from_log_ratio(math.log(rc[1] * rlb))
        assert w == pytest.approx(1.0, abs=1e-9)
        q = lp.parent[v]
        tested[int(lp.kind[q])] = tested.get(int(lp.kind[q]), 0) + 1
    assert all(tested.get(k, 0) > 20 for k in (0, 1, 2)), tested      # emitter, surface, medium parents


def _ball_point(rng, r):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v) * r * rng.uniform() ** (1 / 3)


def test_cli_renders_and_reconstructs(tmp_path):
    """``gdlearn render SCENE --integrator gvpm --transport media --recon l1`` writes the image and the
    buffers (gradients, shift counts); gpt-only shift policies are refused for gvpm and gvpm's for gpt
    (the full image, without --transport: tests/test_gvpm_full.py)."""
    import subprocess
    import sys
    env_cmd = [sys.executable, "-m", "gdlearn", "render", "scenes/fog-box.xml", "--set", "res=8", "--spp", "4",
               "--photons", "2000", "--no-progress"]
    out = tmp_path / "img.npy"
    p = subprocess.run(env_cmd + ["--integrator", "gvpm", "--transport", "media", "--recon", "l1",
                                  "--shift", "simple", "--out", str(out), "--buffers", str(tmp_path / "b")],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    img = np.load(out)
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.mean() > 0
    for name in ("gx", "gy", "primal_base", "shift_null", "shift_failed"):
        assert (tmp_path / "b" / f"{name}.npy").exists()
    assert np.load(tmp_path / "b" / "shift_null.npy").sum() == 0          # the simple shift has no null part
    p = subprocess.run(env_cmd + ["--integrator", "gvpm", "--transport", "media", "--shift", "replay",
                                  "--out", str(out)], capture_output=True, text=True)
    assert p.returncode == 2 and "--shift" in p.stderr
    p = subprocess.run(env_cmd + ["--integrator", "pt", "--shift", "mixed", "--out", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 2
