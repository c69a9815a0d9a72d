"""G-VPM's full image (``transport="all"``, Gruson et al. 2018 with the surface part by Hua et al.
2017's shifts, gdlearn.integrators.photon.gvol_surface): the base estimate is VPM's full image, the
gradients of the whole image are unbiased at fixed radii (PHOTONS.md T3) on the fog box and on a
scene whose surfaces are seen and lit through a bounded medium, the surface reconnection through
media has complementary MIS weights (T4), and the CLI renders it without --transport."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gdlearn.integrators import make
from gdlearn.integrators.base import render
from gdlearn.scene.load import load
from conftest import gradient_residuals, render_cli

#: fixed radii for both parts (surface 0.15, volume 0.25) and no reduction (alpha = 1): each pass is
#: an independent estimate of the blurred full image and the gradients must be unbiased for its
#: differences
FIXED = dict(photons_per_pass=6000, radius=0.15, volume_radius=0.25, alpha=1.0, samples=4)
N_SEEDS = 24
SPP = 16


@pytest.fixture(scope="module")
def fog():
    return load("scenes/fog-box.xml", res=12)


def _runs(scene, seeds=N_SEEDS, spp=SPP, **kw):
    """Per seed: gradient_residuals (gx - FD(base), gy - FD(base), primal - base, gx, FD_x(base))."""
    out = []
    for seed in range(seeds):
        f = render(make("gvpm", scene, seed=500 + seed, **{**FIXED, **kw}), spp=spp)
        out.append(gradient_residuals(f))
        last = f
    return np.array(out), last


@pytest.fixture(scope="module")
def runs(fog):
    return _runs(fog)


@pytest.fixture(scope="module")
def spot_runs():
    """scenes/spot-medium.xml: the floor and back wall seen through a block of smoke bounded by a null
    cube, lit by a spot through it: surface gather points behind camera beams, surface photons whose
    edges cross the block's faces or leave a medium vertex inside it."""
    return _runs(load("scenes/spot-medium.xml", res=14), seeds=24, spp=16, radius=0.12, volume_radius=0.15)


def test_base_estimate_is_vpm(fog):
    """primal_base is VPM's full image for the same seed and fixed radii (same photons, gather points,
    distance samples and emission), to rounding (the order of the sums differs)."""
    kw = dict(FIXED, photons_per_pass=3000)
    g = render(make("gvpm", fog, seed=3, **kw), spp=4)
    v = render(make("vpm", fog, seed=3, **kw), spp=4)
    assert np.allclose(g.images["primal_base"], v.primal, rtol=1e-12, atol=1e-15)
    assert v.primal.mean() > 1e-2 and g.images["shift_surface_reconnected"].sum() > 0


def _z(d):
    m = d.mean(0)
    se = d.std(0, ddof=1) / math.sqrt(len(d))
    ok = se > 1e-12
    return m[ok] / se[ok]


def _check_z(d, name, min_pixels):
    """Over 24 seeds z is Student-t with 23 degrees of freedom: E z^2 = 23/21 = 1.10; 1.5 leaves room
    for a few heavy-tailed pixels (as tests/test_gvpm.py), |z| > 5.5 has probability ~1e-5 per pixel."""
    z = _z(d)
    assert z.size > min_pixels, "too few pixels with a spread: the shifts or the photons are missing"
    assert (z ** 2).mean() < 1.5, f"{name}: mean z^2 {(z ** 2).mean():.2f} (max |z| {np.abs(z).max():.1f})"
    assert np.abs(z).max() < 5.5, f"{name}: max |z| {np.abs(z).max():.1f}"


@pytest.mark.parametrize("i,name", [(0, "gx"), (1, "gy"), (2, "primal")])
def test_unbiased_at_fixed_radius(runs, i, name):
    """gx - (I[x+1] - I[x]) of the full base image (and gy, and the MIS primal - the base) has mean
    zero per pixel (the paired difference cancels most photon noise)."""
    _check_z(runs[0][:, i], name, min_pixels=120)


@pytest.mark.parametrize("i,name", [(0, "gx"), (1, "gy"), (2, "primal")])
def test_unbiased_through_a_bounded_medium(spot_runs, i, name):
    _check_z(spot_runs[0][:, i], name, min_pixels=150)


def test_surface_shifts_succeed(runs, spot_runs):
    """Most surface photon shifts succeed (failing them all would pass the unbiasedness tests
    trivially), and the gradient is less noisy than the difference of two primal estimates. At 12 x 12
    the fog box fails ~30 % (a neighbour outside the image for a third of the pixels, gather points
    straddling the box's edges and corners), spot-medium ~13 %."""
    for d, last in (runs, spot_runs):
        im = last.images
        assert im["shift_surface_reconnected"].sum() > 1.5 * im["shift_surface_failed"].sum()
    d = runs[0]
    interior = (slice(None), slice(1, -1), slice(1, -2))
    ratio = d[:, 3][interior].var(axis=0).mean() / d[:, 4][interior].var(axis=0).mean()
    assert ratio < 0.5, f"var(gx) / var(FD of the primal) = {ratio:.2f}"


@pytest.mark.parametrize("path,min_null", [("scenes/fog-box.xml", 0), ("scenes/spot-medium.xml", 20)])
def test_surface_mis_weights_of_a_pair_sum_to_one(path, min_null):
    """PHOTONS.md T4 for the surface reconnection through media, on real light paths and kernel code:
    a surface photon y_s moved in its plane to y* (the offset photon y'_s = y* when nothing is in the
    way) and the reverse shift back give density ratios r r' = 1 (pass probabilities, parent
    densities, geometry) and power ratios that invert (transmittance, f, geometry), so the balance
    weights of a pair sum to one to 1e-9. Parents: the emitter, walls, medium vertices (fog box);
    edges across the smoke block's null faces (spot-medium)."""
    from gdlearn.integrators.photon.gvol_surface_light import reconnect_surface
    from gdlearn.integrators.photon.gvpm_light import OK, _ancestor
    from gdlearn.integrators.photon.gpm_light import same_point
    from gdlearn.kernels.accel.bvh import STACK_SIZE
    from gdlearn.photons.records import K_SURFACE
    from gdlearn.shifts.mis import mis_weight_from_log_ratio

    g = make("gvpm", load(path, res=8), photons_per_pass=100)
    sa, prm = g.setup.sa, g.gather_params
    lp = g.tracer.trace(7, 0, 0, 1500)
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    rng = np.random.default_rng(5)
    tested, crossing = {}, 0
    for v in lp.photons[(lp.kind[lp.photons] == K_SURFACE) & (lp.parent[lp.photons] >= 0)]:
        q, child, n_null = _ancestor(sa, lp, v)
        if q < 0:
            continue
        nv = lp.nrm[v]
        a = np.cross(nv, [0.3, 0.5, 0.7])
        a /= np.linalg.norm(a)
        ys = lp.pos[v].copy()
        ystar = ys + rng.uniform(-0.15, 0.15) * a + rng.uniform(-0.15, 0.15) * np.cross(nv, a)
        st, f3, rt, d, yh = reconnect_surface(sa, lp, prm, v, tuple(ystar), tuple(nv), tuple(ystar), 1.0, stack)
        if st != OK or not same_point(yh, tuple(ystar), tuple(lp.pos[q]), 1.0):
            continue
        lp2 = type(lp)(*(f.copy() for f in lp))      # the offset light path, as if it had been traced
        lp2.pos[v] = yh
        lp2.d_in[v] = d
        st2, f3b, rtb, _, back = reconnect_surface(sa, lp2, prm, v, tuple(ys), tuple(nv), tuple(ys), 1.0, stack)
        assert st2 == OK and np.allclose(back, ys, atol=1e-9)
        w = mis_weight_from_log_ratio(math.log(rt)) + mis_weight_from_log_ratio(math.log(rtb))
        assert w == pytest.approx(1.0, abs=1e-9)
        assert np.allclose(np.array(f3) * np.array(f3b), 1.0, rtol=1e-9)
        tested[int(lp.kind[q])] = tested.get(int(lp.kind[q]), 0) + 1
        crossing += n_null > 0
    assert all(tested.get(k, 0) > 20 for k in (0, 1, 2)), tested      # emitter, surface, medium parents
    assert crossing >= min_null, crossing


def test_cli_full_image_without_transport(tmp_path):
    """``gdlearn render scenes/fog-box.xml --integrator gvpm --recon l1`` (no --transport) renders the
    full image and writes the surface shift counts and the emission gradients."""
    render_cli(tmp_path, ["scenes/fog-box.xml", "--integrator", "gvpm", "--recon", "l1", "--spp", "2", "--photons", "2000"],
               16, ("gx", "gy", "primal_base", "emission_gx", "shift_surface_reconnected", "shift_null"))
