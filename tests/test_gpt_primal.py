"""gpt's MIS-weighted primal (Kettunen et al. 2015): ``mis_primal`` on hand-made buffers, and the primal
image's unbiasedness against the path tracer (an independent estimator), with a deliberately wrong
split that must fail the same test.

Statistical test: N_SEEDS gpt renders (seeds 1000...) and N_SEEDS pt renders (seeds 5000..., so the two
sets are independent) of a small image; per 2x2 block the Welch t of the difference of the two means.
The truth (equal means) comes from pt, not from the code under test.

* local: every block's |t| below the Bonferroni bound at family-wise false-alarm rate FAMILY_ALPHA
  (Student t with N_SEEDS - 1 dof: fewer than Welch's ~2(N-1), so the bound is conservative);
* omnibus: mean t^2 over the blocks below OMNIBUS_MAX (a small bias spread over many blocks);
* global: the t of the whole image's mean, below the two-sided bound at FAMILY_ALPHA.
"""
import numpy as np
import pytest
from scipy import stats

from gdlearn.integrators import make, render
from gdlearn.integrators.gradients import mis_primal
from gdlearn.integrators.path.gpt_surface.vertex import BROKEN_PRIMAL
from gdlearn.scene.load import load

ROOT = __file__.rsplit("/tests/", 1)[0]
RES = 16
N_SEEDS = 32
SPP = 8
FAMILY_ALPHA = 1e-3
#: t^2 of a t statistic with ~31-62 dof has mean ~1.03-1.07 and variance ~2.2-2.5, so the mean over
#: 64 independent blocks has sd ~0.2; 2.0 is ~4.5 sd above (one-sided p < 1e-4).
OMNIBUS_MAX = 2.0


# --- mis_primal on hand-made buffers ------------------------------------------------------------------

def _reference_mis_primal(out):
    """The formula of the brief, pixel by pixel (an independent loop implementation)."""
    _, h, w, _ = out.shape
    dirs = [(1, 0), (-1, 0), (0, 1), (0, -1)]          # right, left, down, up
    opp = [1, 0, 3, 2]
    res = np.zeros((h, w, 3))
    for y in range(h):
        for x in range(w):
            for k, (dx, dy) in enumerate(dirs):
                qx, qy = x + dx, y + dy
                if 0 <= qx < w and 0 <= qy < h:
                    res[y, x] += out[5 + k, y, x] - out[1 + k, y, x] + out[5 + opp[k], qy, qx]
                else:
                    res[y, x] += out[0, y, x]
    return res / 4


def test_mis_primal_matches_the_formula_on_random_buffers():
    rng = np.random.default_rng(1)
    out = rng.normal(size=(9, 3, 4, 3))
    np.testing.assert_allclose(mis_primal(out), _reference_mis_primal(out), rtol=0, atol=1e-14)


def test_mis_primal_hand_computed_two_pixels():
    """1 x 2 image (p left, q right). p: L = 4, right shift D = 2, S = 3 (so w C = S - D = 1); q: L = 6,
    left shift D = -1, S = 2 (w C = 3). The other three shifts of each pixel leave the image and give
    L. Pair (p, right): 1 + S_left(q) = 3, so I_p = (3 + 3 * 4) / 4 = 15/4; pair (q, left):
    3 + S_right(p) = 6, so I_q = (6 + 3 * 6) / 4 = 6."""
    out = np.zeros((9, 1, 2, 3))
    out[0, 0, 0], out[0, 0, 1] = 4.0, 6.0
    out[1 + 0, 0, 0], out[5 + 0, 0, 0] = 2.0, 3.0      # p, right
    out[1 + 1, 0, 1], out[5 + 1, 0, 1] = -1.0, 2.0     # q, left
    res = mis_primal(out)
    np.testing.assert_allclose(res[0, 0], 15 / 4)
    np.testing.assert_allclose(res[0, 1], 6.0)


def test_all_shifts_failed_gives_the_base_radiance():
    """Failed shifts: D_k = -C, S_k = 0 (weight 1 for the base, STAR Sec. 3.5): every pair gives L."""
    rng = np.random.default_rng(2)
    out = np.zeros((9, 5, 4, 3))
    out[0] = rng.uniform(size=(5, 4, 3))
    out[1:5] = -out[0]
    np.testing.assert_allclose(mis_primal(out), out[0], rtol=0, atol=1e-15)


# --- unbiasedness against pt ----------------------------------------------------------------------------

def _blocks(a):
    a = a.mean(axis=-1)
    a = np.add.reduceat(a, np.arange(0, a.shape[1], 2), axis=1)
    return np.add.reduceat(a, np.arange(0, a.shape[2], 2), axis=2) / 4


def _welch(a, b):
    se = np.sqrt(a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b))
    return np.abs(a.mean(axis=0) - b.mean(axis=0)) / np.maximum(se, 1e-300)


_PT = {}


def _pt(name, sc):
    if name not in _PT:
        _PT[name] = np.stack([render(make("pt", sc, seed=5000 + s, spp_per_pass=SPP), spp=SPP).primal
                              for s in range(N_SEEDS)])
    return _PT[name]


def _check(name, broken=0, shift=None):
    sc = load(f"{ROOT}/scenes/{name}.xml", res=RES)
    frames = []
    for s in range(N_SEEDS):
        integ = make("gpt", sc, seed=1000 + s, spp_per_pass=SPP, shift=shift)
        integ.broken = broken
        frames.append(render(integ, spp=SPP))
    g = np.stack([f.primal for f in frames])
    base = np.stack([f.images["primal_base"] for f in frames])
    p = _pt(name, sc)
    t = _welch(_blocks(g), _blocks(p))
    k = stats.t.isf(FAMILY_ALPHA / (2 * t.size), df=N_SEEDS - 1)
    t_all = float(_welch(g.mean(axis=(1, 2, 3)), p.mean(axis=(1, 2, 3))))
    k_all = stats.t.isf(FAMILY_ALPHA / 2, df=N_SEEDS - 1)
    return t, k, t_all, k_all, g, base


# the default policy on both scenes, and manifold exploration's offsets (chains walked) on the caustics box
@pytest.mark.parametrize("name,shift", [("cornell-box", None), ("caustics-box", None),
                                        ("caustics-box", "halfvector+reconnection+manifold")])
def test_mis_primal_is_unbiased(name, shift):
    t, k, t_all, k_all, g, base = _check(name, shift=shift)
    assert t.max() < k, f"{name}: MIS primal differs from pt in a block: max |t| {t.max():.2f} > {k:.2f}"
    assert float(np.mean(t ** 2)) < OMNIBUS_MAX, f"{name}: mean block t^2 {np.mean(t ** 2):.2f}"
    assert t_all < k_all, f"{name}: image mean differs from pt: |t| {t_all:.2f} > {k_all:.2f}"
    # the point of the MIS primal: lower variance than the base radiance of the same paths
    # (measured per-pixel sd ratio ~0.6 on Cornell; 0.9 leaves room for the seeds)
    ratio = float(np.sqrt(g.var(axis=0).mean() / base.var(axis=0).mean()))
    assert ratio < 0.9, f"{name}: MIS primal sd / base sd = {ratio:.2f}"


def test_unweighted_offset_share_fails_the_same_test():
    """S_k = sum C' instead of sum w C': the offsets' share is counted at full weight next to the base's
    weighted share (about 1.5 I in the interior). The global test must see it."""
    t, k, t_all, k_all, _, _ = _check("cornell-box", broken=BROKEN_PRIMAL)
    assert t_all > k_all and t.max() > k, f"the test cannot see an unweighted split: |t| {t_all:.2f}, {t.max():.2f}"
