"""VPM and the BRE converge to Mitsuba 3's ``volpath`` image on the shipped media scenes (issue 16).

The references are Mitsuba 3's own renders (``tests/references/<case>.npz``, 32 x 32; their image
means carry a relative standard error of about 0.1 %; ``scripts/make_references.py``), independent
of gdlearn. Each estimator renders the same scene file at the same resolution, full transport (the
surface photon gather at the first non-specular vertex, the medium along every camera beam, the
emission exactly). As in ``tests/test_sppm_mitsuba.py``, pixels where the exact emission term is
non-zero (the light seen directly, 2 camera samples a pixel a pass) are left out, dilated by one.

Each case must show within one run relMSE falling with passes (the last pass at most 0.7 x the
value at a quarter of the passes), and the bias bounds stated at OPEN and BOUNDED. The ``.direct``
cases render ``--effects direct,single-scattering`` at max_depth 2: the image comes from
first-vertex photons only and must equal Mitsuba's direct-only image.
"""
import numpy as np
import pytest
import scipy.ndimage as nd

import gdlearn.scene
from gdlearn.crosscheck import store
from gdlearn.experiments.metrics import relmse
from gdlearn.integrators import make

ROOT = store.ROOT
CASES = {c.name: c for c in store.reference_cases()}

#: the image-mean bias must be below 1 %, averaged over two seeds (one run's image mean carries
#: about 0.4 % of noise at this budget: fog-box.direct bre-2d gave +1.10, +0.20, +0.66 % over three
#: seeds). In the global fog of the fog box the kernel's blur is interior, O(r^2) (measured, seed 0:
#: vpm -0.57 %, bre-3d -0.59 %); the single-scattered light of fog-box.direct peaks under the lamp, a
#: convex profile the blur raises, hence 0.7 x the default radius there. The spot-medium's cube
#: is bounded, but its glowing cone keeps clear of the faces the camera looks through. vpm-knn
#: (the 32 nearest photons at every distance sample) keeps its bias as passes go, but its kernel
#: holds as many photons as the default radius does on average, so the fog box's bias is as small.
OPEN = {("fog-box", "vpm"): 1.0, ("fog-box", "vpm-knn"): 1.0, ("fog-box", "bre-3d"): 1.0,
        ("fog-box", "bre-2d"): 1.0,
        ("fog-box.direct", "vpm"): 0.7, ("fog-box.direct", "bre-2d"): 0.7, ("spot-medium", "vpm"): 0.6,
        ("spot-medium", "bre-2d"): 0.6}
#: a bounded medium lit at its faces: a kernel straddling the boundary sees photons on one side only,
#: a bias linear in r (measured on medium-cube.direct: -5.3 % at r = 0.088, -1.6 % at 0.025); the test
#: renders at r and r/2 and asks the bias to fall by a quarter at least and its extrapolation to
#: r = 0, 2 b(r/2) - b(r), to be below 1 %
BOUNDED = {("medium-cube.direct", "bre-3d"): 0.6}
SEEDS = (0, 1)
PHOTONS, PASSES = 100_000, 16
METHODS = {"vpm": {}, "vpm-knn": {"radii": "knn"}, "bre-3d": {"kernel": "3d"}, "bre-2d": {"kernel": "2d"}}


def _load(case, res):
    return gdlearn.scene.load(str(ROOT / case.scene), res=res, **case.mitsuba)


def _run(name, method, scale):
    """(relMSE after a quarter of the passes, after all -- seed 0 --, image-mean bias over SEEDS)."""
    runs = [_run_seed(name, method, scale, seed) for seed in SEEDS]
    return runs[0][0], runs[0][1], float(np.mean([r[2] for r in runs]))


def _run_seed(name, method, scale, seed):
    case = CASES[name]
    ref, _ = store.load_reference(case)
    sc = _load(case, ref.mean.shape[1])
    integ = make("vpm" if method.startswith("vpm") else "bre", sc, seed=seed, photons_per_pass=PHOTONS, effects=case.effects,
                 radius_scale=0.5, volume_radius_scale=scale, **METHODS[method])
    errors = []
    for p in range(1, PASSES + 1):
        f = integ.step()
        if p in (PASSES // 4, PASSES):
            mask = ~nd.binary_dilation(f.images["emission"].max(-1) > 0)
            errors.append(relmse(f.primal[mask], ref.mean[mask]))
    assert mask.mean() > 0.85, f"{name}: the emission mask left out {1 - mask.mean():.0%} of the pixels"
    assert f.stats["nonfinite_samples"] == 0
    return errors[0], errors[1], f.primal[mask].mean() / ref.mean[mask].mean() - 1


@pytest.mark.parametrize("name,method", sorted(OPEN))
def test_open_medium_converges_to_mitsuba(name, method):
    early, late, bias = _run(name, method, OPEN[name, method])
    assert late < 0.7 * early, (early, late)
    assert abs(bias) < 0.01, f"{name} {method}: image-mean bias {bias:+.2%} after {PASSES} passes"


@pytest.mark.parametrize("name,method", sorted(BOUNDED))
def test_bounded_medium_bias_vanishes_with_the_radius(name, method):
    scale = BOUNDED[name, method]
    early, late, b1 = _run(name, method, scale)
    assert late < 0.7 * early, (early, late)
    _, _, b2 = _run(name, method, scale / 2)
    assert abs(b2) < 0.75 * abs(b1), (b1, b2)
    assert abs(2 * b2 - b1) < 0.01, f"{name} {method}: bias {b1:+.2%} at r, {b2:+.2%} at r/2"


def test_a_scene_without_media_is_refused_naming_sppm():
    sc = gdlearn.scene.load(str(ROOT / "scenes" / "cornell-box.xml"), res=8)
    for name in ("vpm", "bre"):
        with pytest.raises(ValueError, match="sppm"):
            make(name, sc, photons_per_pass=10)
