"""gpt (gradient-domain path tracing with shift mappings and Eq. 17 MIS): unbiased gradients per policy,
and deliberately broken variants that must fail the same test.

The statistical test is the replay chapter's (gdlearn.crosscheck.gradients has the full argument): over
N_SEEDS independent seeds, d = gx - (P[x+1] - P[x]) per pixel (gx and the primal P of the *same*
run; both unbiased for I[x+1] - I[x], so E[d] = 0), then

* local: |t| of the mean of d per 2x2 block (channels averaged) below the Bonferroni bound k for
  all blocks of gx and gy at family-wise false-alarm rate FAMILY_ALPHA = 1e-3 (Student t, N-1 dof);
* global: the projection of d on an independent path-traced pilot's gradients (matched filter),
  three two-sided tests (gx, gy, both) at the same family level;
* omnibus: the mean of t^2 over all blocks of gx and gy below OMNIBUS_MAX. A bias that is neither
  proportional to the gradients nor concentrated in one block (a wrong Jacobian) shows here.

The truth (E[d] = 0) comes from the primal path tracer, not from the shifts under test. The seeds
are fixed, so nothing flickers; a correct estimator fails about once per thousand seed sets.
"""
import copy

import numpy as np
import pytest

from gdlearn.crosscheck import gradients as G
from gdlearn.crosscheck.gradients import FAMILY_ALPHA, OMNIBUS_MAX, block_t, omnibus, projected_t  # noqa: F401
from gdlearn.integrators import make, render
from gdlearn.integrators.path.gpt_surface.vertex import BROKEN_HV_JACOBIAN, BROKEN_JACOBIAN, BROKEN_MIS, BROKEN_UNPAIRED
from gdlearn.scene.load import load
from gdlearn.scene.model import BSDF, rgb
from gdlearn.shifts.policy import POLICIES, stats_dict

ROOT = __file__.rsplit("/tests/", 1)[0]
RES = 16
N_SEEDS = 32
SPP = 8
PILOT_SPP = 128


@pytest.mark.parametrize("effects", ["direct", "diffuse-interreflection,glossy"])
def test_walk_left_out_only_where_it_changes_nothing_rendered(effects):
    """Where the request renders neither specular nor caustic paths, ``select_kernel`` runs
    halfvector+reconnection for the manifold policy. That is the same image, because only paths of
    those classes can cross a walked chain: forcing the manifold kernel gives the same buffers."""
    from gdlearn.integrators.path.gpt import MANIFOLD_POLICY, gpt_manifold_rows, gpt_rows
    from gdlearn.integrators.path.gpt_surface.manifold import manifold_table
    sc = _scene("caustics-box")
    plain = make("gpt", sc, seed=4, spp_per_pass=4, shift=MANIFOLD_POLICY, effects=effects, max_depth=6)
    assert plain.kernel is gpt_rows
    forced = make("gpt", sc, seed=4, spp_per_pass=4, shift=MANIFOLD_POLICY, effects=effects, max_depth=6)
    forced.kernel, forced.extra = gpt_manifold_rows, (manifold_table(forced.setup.scene, forced.setup.sa),)
    forced.policy = POLICIES[MANIFOLD_POLICY]
    a, _, _ = plain.trace(0, 4)
    b, st_b, _ = forced.trace(0, 4)
    assert np.abs(a).max() > 0
    np.testing.assert_array_equal(a, b)
    # with paths long enough for chains, the forced kernel did walk them: the equality is not vacuous
    if effects != "direct":
        assert stats_dict(st_b)["manifold"]["run"] > 0
    assert make("gpt", sc, shift=MANIFOLD_POLICY, max_depth=6).kernel is gpt_manifold_rows


def _scene(name):
    """A scene file by name, or a variant of the caustics box with rough interfaces:
    ``near-specular`` (rough mirror alpha 0.02 and rough glass 0.03, below the roughness threshold
    0.05: half-vector copies with their Jacobian, reflection and refraction) and ``glossy``
    (alpha 0.3: connectable glossy vertices, reconnections through rough glass)."""
    if name == "roughplastic":
        # the Cornell box with a rough plastic floor and back wall (alpha 0.3: a glossy coating over
        # a diffuse base), for effects-restricted gradients that must split its lobes per path
        sc = load(f"{ROOT}/scenes/cornell-box.xml", res=RES)
        for shape in sc.shapes:
            if shape.id in ("floor", "back"):
                shape.bsdf = BSDF("roughplastic", alpha=0.3, distribution="ggx", reflectance=rgb(0.15))
        return sc
    alphas = {"near-specular": (0.02, 0.03), "glossy": (0.3, 0.3)}
    if name not in alphas:
        return load(f"{ROOT}/scenes/{name}.xml", res=RES)
    sc = load(f"{ROOT}/scenes/caustics-box.xml", res=RES)
    for shape in sc.shapes:
        if shape.bsdf.type in ("conductor", "dielectric"):
            shape.bsdf = copy.copy(shape.bsdf)
            shape.bsdf.alpha = alphas[name][0 if shape.bsdf.type == "conductor" else 1]
            shape.bsdf.type = "rough" + shape.bsdf.type
    return sc


def _frames(scene, shift, broken=0, n=N_SEEDS, **opts):
    out = []
    for seed in range(n):
        integ = make("gpt", scene, seed=1000 + seed, spp_per_pass=SPP, shift=shift, **opts)
        integ.broken = broken
        out.append(render(integ, spp=SPP))
    return out


def differences(frames):
    # the base radiance L (pt's estimator), not the MIS primal: the gradients are tested on their own
    return G.differences(frames, "primal_base")


_PILOTS = {}


def _pilot(name):
    # seed 7 is not among the test seeds (1000...): the pilot is independent of the frames
    if name not in _PILOTS:
        _PILOTS[name] = render(make("pt", _scene(name), seed=7, spp_per_pass=PILOT_SPP // 4), spp=PILOT_SPP)
    return _PILOTS[name]


@pytest.mark.parametrize("name,shift,effects", [("cornell-box", "halfvector+reconnection", None),
                                                ("cornell-box", "replay+reconnection", None),
                                                ("caustics-box", "halfvector+reconnection", None),
                                                ("caustics-box", "replay+reconnection", None),
                                                ("caustics-box", "halfvector+replay+reconnection", None),
                                                ("caustics-box", "replay", None),
                                                ("near-specular", "halfvector+reconnection", None),
                                                ("near-specular", "replay+reconnection", None),
                                                ("near-specular", "halfvector+replay+reconnection", None),
                                                ("glossy", "halfvector+reconnection", None),
                                                ("glossy", "replay+reconnection", None),
                                                ("mesh", "replay+reconnection", None),
                                                # the default policy on rough plastic and rough metal
                                                ("glossy-box", "halfvector+replay+reconnection", None),
                                                ("caustics-box", "replay+reconnection", "caustics"),
                                                # each path's own class decides: an offset's
                                                # class may differ from its base's
                                                ("caustics-box", "halfvector+reconnection", "caustics"),
                                                ("glossy", "halfvector+reconnection", "glossy,specular"),
                                                # a rough plastic's two lobes: offsets keep the
                                                # base's sampled label, weighted P_y / P_x (the
                                                # old rule, the offset classed diffuse, is caught
                                                # by test_effects_roughplastic, not here: measured
                                                # max |t| 3.9 < k 5.35)
                                                ("roughplastic", "halfvector+reconnection", "glossy"),
                                                ("roughplastic", "halfvector+reconnection",
                                                 "diffuse-interreflection")])
def test_gradients_are_unbiased(name, shift, effects):
    dx, dy = differences(_frames(_scene(name), shift, effects=effects))
    tx, ty, k = block_t(dx, dy)
    assert tx.max() < k and ty.max() < k, (
        f"{shift} on {name}: gradients differ from the primal's finite differences in some block: "
        f"max |t| gx {tx.max():.2f}, gy {ty.max():.2f} > k = {k:.2f}")
    assert omnibus(tx, ty) < OMNIBUS_MAX, f"{shift} on {name}: mean block t^2 {omnibus(tx, ty):.2f}"
    px, py, pxy, kp = projected_t(dx, dy, _pilot(name))
    assert max(px, py, pxy) < kp, (
        f"{shift} on {name}: gradients biased along the image's gradients: |t| {px:.2f}, {py:.2f}, {pxy:.2f} "
        f"> {kp:.2f}")


def test_mis_weight_one_on_both_sides_fails_the_same_test():
    """Eq. 17 replaced by w = 1 for the forward *and* the backward shift: every successfully shifted
    pair is counted twice, a bias of the size of the gradient itself. The matched filter must see it."""
    dx, dy = differences(_frames(_scene("cornell-box"), "halfvector+reconnection", broken=BROKEN_MIS))
    px, py, pxy, kp = projected_t(dx, dy, _pilot("cornell-box"))
    assert px > kp and py > kp, f"the test cannot see doubled gradients: |t| gx {px:.2f}, gy {py:.2f} <= {kp:.2f}"


def test_reconnection_jacobian_one_fails_the_same_test():
    """The reconnection's solid-angle Jacobian (GPM Eq. 4 with area Jacobian 1) replaced by 1: the
    offset's contribution and MIS weight are then wrong wherever the two segments differ in length
    and angle -- at every diffuse reconnection of the Cornell box."""
    dx, dy = differences(_frames(_scene("cornell-box"), "halfvector+reconnection", broken=BROKEN_JACOBIAN))
    tx, ty, _ = block_t(dx, dy)
    # measured 4.3 (0.95 for the correct Jacobian): far above the threshold the correct one passes
    assert omnibus(tx, ty) > OMNIBUS_MAX, f"the test cannot see a Jacobian of 1: mean t^2 {omnibus(tx, ty):.2f}"


def test_unpaired_technique_weighted_by_eq17_fails_the_same_test():
    """replay+reconnection replays an offset onto the glass or the mirror where its base is diffuse;
    the offset has no next-event technique there (density 0), so the base's sample must keep weight 1
    (gpt_mixed.unpaired). Weighted by Eq. 17 instead (gpt_shift.BROKEN_UNPAIRED), half of it is lost
    along the spheres' silhouettes: measured max block |t| 5.97 (k 5.35), mean t^2 2.60 (the correct
    policy: 2.38 and 1.02)."""
    dx, dy = differences(_frames(_scene("caustics-box"), "replay+reconnection", broken=BROKEN_UNPAIRED))
    tx, ty, k = block_t(dx, dy)
    assert omnibus(tx, ty) > OMNIBUS_MAX and max(tx.max(), ty.max()) > k, (
        f"the test cannot see the unpaired weight: block |t| {tx.max():.2f}, {ty.max():.2f} <= {k:.2f}, "
        f"mean t^2 {omnibus(tx, ty):.2f}")


def test_halfvector_jacobian_one_fails_the_same_test():
    """J_w of the half-vector copy (Walter's dh/dw ratio, STAR Eq. 15) replaced by 1 at the rough
    mirror and glass of the near-specular box: measured max block |t| ~20, mean t^2 ~11."""
    dx, dy = differences(_frames(_scene("near-specular"), "halfvector+reconnection", broken=BROKEN_HV_JACOBIAN))
    tx, ty, k = block_t(dx, dy)
    assert max(tx.max(), ty.max()) > k and omnibus(tx, ty) > OMNIBUS_MAX, (
        f"the test cannot see J_w = 1: block |t| {tx.max():.2f}, {ty.max():.2f} <= {k:.2f}, "
        f"mean t^2 {omnibus(tx, ty):.2f}")


def test_primal_is_the_path_tracer_without_roulette():
    """The base paths are pt's, sample for sample (same random numbers); only Russian roulette differs
    (gpt takes max(base, offset) throughput), so with roulette off the primal is pt's up to rounding."""
    sc = _scene("caustics-box")
    g = make("gpt", sc, seed=3, spp_per_pass=2, shift="halfvector+reconnection+manifold")
    p = make("pt", sc, seed=3, spp_per_pass=2)
    g.setup.rr_depth = p.setup.rr_depth = 1 << 20
    a, b = render(g, spp=4).images["primal_base"], render(p, spp=4).primal
    assert b.mean() > 0
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)   # only the order of products differs


def test_stats_and_hard_cases_stay_finite():
    """Deep caustic paths (glass + mirror, max_depth 12): every image finite, no sample dropped as
    non-finite, each shift kind ran, failures counted, borders undefined (zero)."""
    sc = _scene("caustics-box")
    f = render(make("gpt", sc, seed=11, spp_per_pass=4, max_depth=12, shift="halfvector+reconnection+manifold"), spp=8)
    for name in ("primal", "primal_base", "gx", "gy"):
        assert np.all(np.isfinite(f.images[name]))
    assert f.stats["nonfinite_samples"] == 0
    for action in ("halfvector", "reconnection"):
        assert f.stats[f"shift_{action}_run"] > 0
        assert f.stats[f"shift_{action}_run"] == f.stats[f"shift_{action}_ok"] + f.stats[f"shift_{action}_failed"]
    assert f.stats["shift_fail_failed"] > 0 and f.stats["shift_replay_run"] == 0
    assert np.all(f.gx[:, -1] == 0) and np.all(f.gy[-1, :] == 0)
    # the mixed policy on the same deep paths: finite, no Kettunen-style "fail", its failures are
    # replays (or half-vector copies) whose backward shift would reconnect
    f = render(make("gpt", sc, seed=11, spp_per_pass=4, max_depth=12, shift="halfvector+replay+reconnection"), spp=8)
    assert all(np.all(np.isfinite(f.images[n])) for n in ("primal", "primal_base", "gx", "gy"))
    assert f.stats["nonfinite_samples"] == 0 and f.stats["shift_fail_run"] == 0
    assert f.stats["shift_replay_failed"] > 0 and f.stats["shift_halfvector_run"] > 0


def test_bad_options_are_clear_errors():
    sc = _scene("cornell-box")
    with pytest.raises(ValueError, match="unknown shift policy"):
        make("gpt", sc, shift="teleport")
    assert not make("gpt", sc, shift="halfvector+reconnection+manifold").manifold   # no specular chain here
    fog = load(f"{ROOT}/scenes/fog-box.xml", res=RES)
    with pytest.raises(ValueError, match="manifold exploration is not implemented in media"):
        make("gpt", fog, shift="halfvector+reconnection+manifold")


def test_media_dispatch_to_the_volume_kernel():
    """Scenes with media run gpt_volume_rows (same signature and out contract), imported lazily."""
    from gdlearn.integrators.path.gpt_volume.lockstep import gpt_volume_rows
    from gdlearn.integrators.path.gpt import gpt_rows
    assert make("gpt", load(f"{ROOT}/scenes/fog-box.xml", res=RES)).kernel is gpt_volume_rows
    assert make("gpt", _scene("cornell-box")).kernel is gpt_rows


def test_default_policy_and_the_manifold_walk_follow_the_plan():
    """shift=None: halfvector+replay+reconnection everywhere (manifold exploration lost at equal time on
    the glass scenes: gpt.DEFAULT_RULE); asked for, the manifold walk compiles only where the plan
    renders specular chains over analytic specular shapes; the CLI offers every supported policy."""
    from gdlearn.commands.render import SHIFT_CHOICES
    from gdlearn.integrators.path.gpt import DEFAULT_POLICY, MANIFOLD_POLICY, SUPPORTED
    assert SHIFT_CHOICES == SUPPORTED and MANIFOLD_POLICY in SUPPORTED
    caustics = _scene("caustics-box")
    g = make("gpt", caustics)
    assert g.shift == DEFAULT_POLICY and not g.manifold
    g = make("gpt", caustics, shift=MANIFOLD_POLICY)
    assert g.shift == MANIFOLD_POLICY and g.manifold
    # asking for direct light only renders no caustic: the walk would never run, so it is not compiled
    g = make("gpt", caustics, shift=MANIFOLD_POLICY, effects="direct")
    assert not g.manifold and g.policy == POLICIES["halfvector+reconnection"]
    assert not make("gpt", _scene("cornell-box"), shift=MANIFOLD_POLICY).manifold
    assert make("gpt", _scene("cornell-box")).shift == DEFAULT_POLICY
    assert make("gpt", load(f"{ROOT}/scenes/fog-box.xml", res=RES)).shift == DEFAULT_POLICY
    assert make("gpt", caustics, shift="replay").shift == "replay"
