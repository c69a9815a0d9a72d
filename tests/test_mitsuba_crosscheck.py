"""Cross-check gdlearn's path tracer against Mitsuba 3 on every shipped scene (issue 2).

The Mitsuba references are cached in ``tests/references/`` (``scripts/make_references.py``: 32 x 32
pixels, 8 independent seeds x 1024 spp, mean and per-pixel standard error). gdlearn renders the same
scene file at the same resolution with 4 independent seeds; :func:`gdlearn.crosscheck.compare.compare`
then requires, for 4 x 4-pixel blocks and each channel,

    |z| = |m_gdlearn - m_mitsuba| / sqrt(se_gdlearn^2 + se_mitsuba^2) < t.isf(alpha / (2 m), dof)

(Welch's t with Welch-Satterthwaite degrees of freedom; Bonferroni over the m = 3 * 64 block tests
plus the 3 channel means, family-wise false alarm alpha = 1e-3: about |z| < 4.6), and the image mean
to agree within 3 % per channel. The tolerance is calibrated from the noise of both renderers, not
picked: the tests below first prove the harness on Mitsuba alone (an independent Mitsuba render is
accepted with mean z^2 ~ 1; a 5 % brighter light, a flipped image and missing indirect light are
rejected), then compare gdlearn.

Tests that render with Mitsuba skip when it is not installed (the ``[ref]`` extra); the gdlearn
comparisons only need the cached references and run regardless.
"""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from gdlearn.crosscheck import store
from gdlearn.crosscheck.compare import ImageStats, compare

HAVE_MITSUBA = importlib.util.find_spec("mitsuba") is not None
needs_mitsuba = pytest.mark.skipif(
    not HAVE_MITSUBA, reason="Mitsuba 3 is not installed: pip install -e '.[ref]' "
                             "(the README's test command installs it)")

CASES = {c.name: c for c in store.reference_cases()}
#: Cases whose image mean cannot be made precise enough for REL_BOUND at test cost; the block z-tests
#: and the REL_BOUND itself still apply, only the "is the bound >= 3 standard errors" check is waived.
INFINITE_VARIANCE = {
    "test-single-scatter": "a point light inside the medium: single scattering near it has infinite "
                           "variance (~1/d^2 NEE), so the image mean's standard error does not shrink "
                           "like 1/sqrt(spp); measured: gdlearn's relative se 1.4 % at 4864 spp",
}
#: Known, explained mismatches (strict xfail: the test turns red again once the cause is fixed, so
#: the marker must then be removed). Found by this cross-check; see the reason for the evidence.
KNOWN_MISMATCH: dict[str, str] = {}   # e.g. spot-medium had a cube face coplanar with the floor (fixed)
#: Family-wise false-alarm probability of one image comparison (Bonferroni inside compare()).
ALPHA = 1e-3
#: The image mean must agree to 3 % per channel: below the 5 % light change the harness must catch,
#: and (asserted in the tests) at least 3 standard errors of the relative mean difference wide, so
#: noise alone trips it with probability < 0.3 % (normal two-sided tail at 3 sigma). The image mean
#: of these scenes is noisy (per-sample relative sd ~4 in the Cornell box, ~7 in the fog box: a few
#: pixels straddle the light's edge), so a tighter fixed bound would need far more samples.
REL_BOUND = 0.03
#: gdlearn's side: K independent batches (passes of one progressive render, whose per-pass means are
#: independent by the counter-based RNG: sample indices never repeat); spp per batch from the
#: reference's own noise (see _gd_spp). 16 batches: the per-pixel standard error has 15 degrees of
#: freedom, enough to stay honest for the heavy-tailed caustic paths (4 seeds were not).
GD_BATCHES = 16
#: Target relative standard error of gdlearn's image mean: with the reference's (<= 0.4 %) the
#: combined error stays < 1 %, i.e. REL_BOUND is >= 3 standard errors wide.
GD_REL_SE = 0.008
#: Cases not compared with gdlearn, and why (evidence in the reason; the analytic tests cover them).
KNOWN_REFERENCE_BIAS = {
    "test-furnace-sphere": "Mitsuba 3.9 itself misses the analytic furnace value here: scalar_rgb gives "
                           "2.018 +- 0.0004 (llvm_ad_rgb 2.002) for Le / (1 - rho) = 2 (max_depth 2: 1.5103 "
                           "vs 1.5), a float32 bias far beyond the noise; gdlearn gives 2.0002, so the "
                           "comparison would flag Mitsuba, not gdlearn. tests of the analytic furnace "
                           "value cover this scene.",
}
#: Mitsuba stand-in for the harness tests (it plays gdlearn's part: same batch count, same spp rule);
#: its seeds are independent of the references' (1000...).
MI_SEEDS = tuple(range(1, GD_BATCHES + 1))


def _check_rel_bound_has_power(a: ImageStats, b: ImageStats):
    """The image-mean bound must be >= 3 standard errors of the relative mean difference."""
    n = a.mean.shape[0] * a.mean.shape[1]
    se = np.sqrt(a.var.sum((0, 1)) + b.var.sum((0, 1))) / n
    rel_se = se / np.maximum(b.mean.mean((0, 1)), 1e-12)
    assert np.all(3 * rel_se < REL_BOUND), f"image mean too noisy for the REL_BOUND: rel se {rel_se}"


def _gd_spp(ref: ImageStats, settings: dict) -> int:
    """Samples per pixel per batch so that gdlearn's image mean has relative standard error ~GD_REL_SE,
    assuming gdlearn's per-sample noise equals Mitsuba's (measured from the reference itself). Kept
    per batch in [64, 512]: at least 64 because Student's t needs batch means that are not too skewed
    -- with 16 spp per batch, Mitsuba against its own reference on the caustics box (rare, bright
    paths through the glass) fails (mean z^2 2.6-3.4), at 64 it passes (1.0-1.4); at most 512 so
    that no case costs more than a few seconds of rendering."""
    n = ref.mean.shape[0] * ref.mean.shape[1]
    rel_se_ref = np.sqrt(ref.var.sum((0, 1))) / n / np.maximum(ref.mean.mean((0, 1)), 1e-12)
    per_sample_sd = float(rel_se_ref.max()) * np.sqrt(n * len(settings["seeds"]) * settings["spp"])
    spp_total = (per_sample_sd / GD_REL_SE) ** 2 / n
    return int(np.clip(8 * np.ceil(spp_total / GD_BATCHES / 8), 64, 512))


def _reference(name: str) -> ImageStats:
    ref, _ = store.load_reference(CASES[name])
    return ref


def _perturb(s: ImageStats, kind: str) -> ImageStats:
    if kind == "light+5%":      # light transport is linear in the emitted radiance (one light)
        return ImageStats(s.mean * 1.05, s.var * 1.05 ** 2, s.dof)
    if kind == "flip-vertical":
        return ImageStats(s.mean[::-1], s.var[::-1], s.dof[::-1])
    if kind == "flip-horizontal":
        return ImageStats(s.mean[:, ::-1], s.var[:, ::-1], s.dof[:, ::-1])
    raise ValueError(kind)


# -- the references themselves ---------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(CASES))
def test_reference_present_and_fresh(name):
    """Every case has a reference made from the scene file as it is now (else: the fix to run)."""
    ref, settings = store.load_reference(CASES[name])
    assert ref.mean.shape == (store.RES, store.RES, 3)
    assert np.isfinite(ref.mean).all() and np.isfinite(ref.var).all()
    assert ref.mean.mean() > 0, f"{name}: the Mitsuba reference is black; is the scene lit?"


# -- the statistics, on synthetic images whose truth is known ------------------------------------------
def _synthetic(rng, truth, sd, k):
    return ImageStats.from_samples(truth + sd * rng.standard_normal((k,) + truth.shape))


def test_compare_false_alarm_rate_on_synthetic_noise():
    """Two unbiased estimates of one image (heteroscedastic Gaussian noise, K = 4 vs K = 8 images)
    pass at the family-wise rate 1 - alpha: with alpha = 0.1 over 300 trials the false alarms are
    Binomial(300, <= 0.1) (Bonferroni is conservative); 0.1 + 3 sd = 0.152 bounds the rate."""
    rng = np.random.default_rng(7)
    truth = rng.uniform(0.05, 1.0, (32, 32, 3))
    sd = 0.5 * truth * rng.uniform(0.2, 2.0, truth.shape)
    alarms = sum(not compare(_synthetic(rng, truth, sd, 4), _synthetic(rng, truth, sd, 8), alpha=0.1,
                             rel_bound=1.0).ok for _ in range(300))
    assert alarms / 300 < 0.1 + 3 * np.sqrt(0.1 * 0.9 / 300), alarms


def test_compare_detects_small_bias_on_synthetic_noise():
    """A 3 % bias in one 4x4 block (z ~ 10) is found, at that block; zero noise with a difference is
    infinitely significant; identical noise-free images pass."""
    rng = np.random.default_rng(8)
    truth = np.ones((32, 32, 3))
    biased = truth.copy()
    biased[8:12, 8:12] *= 1.03
    sd = 0.02    # block se: test 0.02/sqrt(4*16), ref 0.02/sqrt(8*16): combined 0.0031 -> z = 0.03/0.0031 ~ 10
    c = compare(_synthetic(rng, biased, sd, 4), _synthetic(rng, truth, sd, 8), rel_bound=1.0)
    assert not c.blocks_ok and c.worst()["rows"] == (8, 12) and c.worst()["cols"] == (8, 12)
    exact = ImageStats(truth, np.zeros_like(truth), np.ones_like(truth))
    assert compare(exact, exact).ok
    assert not compare(ImageStats(biased, exact.var, exact.dof), exact).ok


def test_a_noisy_mean_beyond_the_bound_is_inconclusive_a_precise_one_a_mismatch():
    """The image mean 8 % high everywhere. Noisy (relative se of the mean ~6 %: the 5 % bound is
    less than 3 se wide): inconclusive, which the fuzzer answers with more samples. Precise (se
    ~0.1 %, every block z ~ 10): a mismatch, never inconclusive. Within the bound: no verdict issue."""
    rng = np.random.default_rng(9)
    truth = np.ones((16, 16, 3))
    noisy = compare(_synthetic(rng, 1.08 * truth, 2.5, 8), _synthetic(rng, truth, 2.5, 16), rel_bound=0.05)
    assert noisy.blocks_ok and not noisy.ok and not noisy.mean_resolved and noisy.inconclusive
    precise = compare(_synthetic(rng, 1.08 * truth, 0.02, 8), _synthetic(rng, truth, 0.02, 16), rel_bound=0.05)
    assert precise.mean_resolved and not precise.ok and not precise.inconclusive
    fine = compare(_synthetic(rng, truth, 0.02, 8), _synthetic(rng, truth, 0.02, 16), rel_bound=0.05)
    assert fine.ok and not fine.inconclusive


# -- the harness, proven on Mitsuba alone ------------------------------------------------------------
_mi_cache: dict = {}


def _mitsuba_standin(name: str, variant: str = "scalar_rgb", **extra) -> ImageStats:
    from gdlearn.crosscheck.mitsuba import render_mitsuba

    case = CASES[name]
    key = (name, variant, tuple(sorted(extra.items())))
    if key not in _mi_cache:
        d = dict(case.mitsuba, res=store.RES, **extra)
        spp = _gd_spp(*store.load_reference(case))
        imgs = [render_mitsuba(store.ROOT / case.scene, spp, s, variant, 2, **d) for s in MI_SEEDS]
        _mi_cache[key] = ImageStats.from_samples(imgs)
    return _mi_cache[key]


@needs_mitsuba
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box.direct", "fog-box.direct", "caustics-box"])
def test_harness_accepts_independent_mitsuba_render(name):
    """Mitsuba at other seeds passes, and its z-scores are calibrated: mean z^2 ~ 1. With 64 blocks
    whose R, G, B z are strongly correlated (~64 independent values), mean z^2 has sd ~ sqrt(2/64)
    = 0.18; [0.4, 1.8] is > 3 sd either side (plus room for Student-t tails)."""
    ref, test = _reference(name), _mitsuba_standin(name)
    c = compare(test, ref, alpha=ALPHA, rel_bound=REL_BOUND)
    assert c.ok, c.summary()
    assert 0.4 < c.mean_z2 < 1.8, c.summary()
    _check_rel_bound_has_power(test, ref)


@needs_mitsuba
@pytest.mark.mitsuba
@pytest.mark.parametrize("kind", ["light+5%", "flip-vertical", "flip-horizontal"])
def test_harness_rejects_perturbed_image(kind):
    """The same accepted Mitsuba render, perturbed, must be rejected: the comparison can fail."""
    ref, test = _reference("cornell-box"), _mitsuba_standin("cornell-box")
    c = compare(_perturb(test, kind), ref, alpha=ALPHA, rel_bound=REL_BOUND)
    assert not c.ok, f"a {kind} image was accepted: {c.summary()}"


@needs_mitsuba
@pytest.mark.mitsuba
def test_harness_rejects_brighter_light_in_scene():
    """A 5 % brighter emitter set in Mitsuba's scene itself (not by scaling pixels) is rejected."""
    import mitsuba as mi

    from gdlearn.crosscheck.mitsuba import set_threads

    mi.set_variant("scalar_rgb")
    set_threads(2)
    scene = mi.load_file(str(store.ROOT / "scenes/cornell-box.xml"), res=str(store.RES))
    params = mi.traverse(scene)
    keys = [k for k in params.keys() if k.endswith("emitter.radiance.value")]
    assert keys, "no area emitter radiance found in the Cornell box"
    for k in keys:
        params[k] = params[k] * 1.05
    params.update()
    spp = _gd_spp(*store.load_reference(CASES["cornell-box"]))
    imgs = [np.array(mi.render(scene, seed=s, spp=spp), dtype=np.float64)[..., :3] for s in MI_SEEDS]
    c = compare(ImageStats.from_samples(imgs), _reference("cornell-box"), alpha=ALPHA, rel_bound=REL_BOUND)
    assert not c.ok, c.summary()


@needs_mitsuba
@pytest.mark.mitsuba
def test_harness_rejects_missing_indirect_light():
    """Direct light only (max_depth 2) against the full Cornell box: a transport bug is caught."""
    c = compare(_mitsuba_standin("cornell-box.direct"), _reference("cornell-box"), alpha=ALPHA,
                rel_bound=REL_BOUND)
    assert not c.ok, c.summary()


@needs_mitsuba
@pytest.mark.mitsuba
def test_llvm_variant_matches_scalar_reference():
    """Mitsuba's two back-ends agree within the calibrated tolerance (skips without libLLVM >= 16)."""
    from gdlearn.crosscheck.mitsuba import variant_works

    ok, why = variant_works("llvm_ad_rgb")
    if not ok:
        pytest.skip(why)
    c = compare(_mitsuba_standin("cornell-box", "llvm_ad_rgb"), _reference("cornell-box"),
                alpha=ALPHA, rel_bound=REL_BOUND)
    assert c.ok, c.summary()


# -- gdlearn's path tracer against the references ------------------------------------------------------
_gd_cache: dict = {}


def _gdlearn_render(name: str, integrator: str = "pt") -> ImageStats:
    try:
        from gdlearn.integrators import get, make
        from gdlearn.scene.load import load
        get(integrator)
    except (ImportError, AttributeError) as err:
        pytest.skip(f"gdlearn's {integrator} or scene loader is not importable yet: {err}")
    case = CASES[name]
    key = name if integrator == "pt" else (name, integrator)
    if key not in _gd_cache:
        ref, settings = store.load_reference(case)
        spp = _gd_spp(ref, settings)
        scene = load(store.ROOT / case.scene, res=store.RES)
        opts = dict(spp_per_pass=spp, threads=2)
        if case.effects:
            opts["effects"] = list(case.effects)
        integ = make(integrator, scene, seed=1, **opts)
        integ.warmup()
        imgs, prev = [], None
        for _ in range(GD_BATCHES):     # this pass's mean, recovered from the running mean
            f = integ.step()
            imgs.append(f.primal * f.spp - (prev.primal * prev.spp if prev else 0.0))
            imgs[-1] /= f.spp - (prev.spp if prev else 0)
            prev = f
        _gd_cache[key] = ImageStats.from_samples(imgs)
    return _gd_cache[key]


@pytest.mark.slow
@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=KNOWN_MISMATCH[n]))
    if n in KNOWN_MISMATCH else n for n in sorted(CASES)])
def test_gdlearn_pt_matches_mitsuba(name):
    """gdlearn's PT converges to Mitsuba 3's image on every shipped scene (and the direct cases)."""
    if name in KNOWN_REFERENCE_BIAS:
        pytest.skip(KNOWN_REFERENCE_BIAS[name])
    ref, test = _reference(name), _gdlearn_render(name)
    c = compare(test, ref, alpha=ALPHA, rel_bound=REL_BOUND)
    assert c.ok, f"{name}: {c.summary()}"
    if name not in INFINITE_VARIANCE:
        _check_rel_bound_has_power(test, ref)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["light+5%", "flip-vertical"])
def test_gdlearn_comparison_can_fail(kind):
    """The same comparison rejects gdlearn's Cornell box once perturbed."""
    c = compare(_perturb(_gdlearn_render("cornell-box"), kind), _reference("cornell-box"),
                alpha=ALPHA, rel_bound=REL_BOUND)
    assert not c.ok, c.summary()


#: Bounded media lit from outside: the gradient integrators' primal images go through the same volume
#: path code (gpt-replay calls radiance_volpath; gpt's base path shares shadow_transmittance), so
#: they must converge to Mitsuba's image too. Same comparison, same tolerances as pt's.
GRADIENT_MEDIA_CASES = ("medium-cube.direct", "test-medium-room")


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["gpt-replay", "gpt"])
@pytest.mark.parametrize("name", GRADIENT_MEDIA_CASES)
def test_gdlearn_gradient_primal_matches_mitsuba_in_bounded_media(name, integrator):
    """gpt-replay's and gpt's primal images match Mitsuba 3 on bounded media lit from outside."""
    ref, test = _reference(name), _gdlearn_render(name, integrator)
    c = compare(test, ref, alpha=ALPHA, rel_bound=REL_BOUND)
    assert c.ok, f"{name} ({integrator}): {c.summary()}"
