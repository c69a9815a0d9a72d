"""The red-black split layout (gdlearn.reconstruct.split) and the V-cycle's stencils on it
(gdlearn.reconstruct.mg_kernels), each against a plain numpy version on the natural padded layout
-- the semantics the natural-layout kernels had before the split layout replaced them -- on even
and odd sizes (an odd width leaves a spare slot in the odd half, an odd height a coarse cell of
one row), with shared (1) and per-channel (3) weights."""
import numpy as np
import pytest

from gdlearn.reconstruct import mg_fused as mf
from gdlearn.reconstruct import mg_kernels as mk
from gdlearn.reconstruct.planar import apply_planar, from_planar, to_planar
from gdlearn.reconstruct.split import apply_split, from_split, split_shape, to_split

SIZES = [(7, 9), (8, 10), (9, 12), (6, 11), (1, 6), (5, 1)]


def spl(a, dtype=np.float64):
    """Natural padded C x (H+2) x (W+2) -> split layout."""
    return to_split(from_planar(a), dtype)


def nat(s, w):
    """Split layout -> natural padded (float64), frame 0."""
    return to_planar(from_split(s, w))


def problem(h, w, cw, c=3, seed=0):
    """Random natural padded weights spanning e^6 (masked last column / row 0), vectors z, b and
    the inverse diagonal, all float64."""
    rng = np.random.default_rng(seed)
    w0, wx, wy = (to_planar(np.exp(rng.uniform(-3, 3, (h, w, cw)))) for _ in range(3))
    w0 *= 0.04
    wx[:, :, w] = 0.0
    wy[:, h, :] = 0.0
    z, b = (to_planar(rng.standard_normal((h, w, c))) for _ in range(2))
    d = np.zeros_like(w0)
    d[:, 1:-1, 1:-1] = (w0[:, 1:-1, 1:-1] + wx[:, 1:-1, 1:-1] + wx[:, 1:-1, :-2]
                        + wy[:, 1:-1, 1:-1] + wy[:, :-2, 1:-1])
    invd = np.where(d > 0, 1 / np.where(d > 0, d, 1), 0.0)
    return w0, wx, wy, z, b, invd


def a_times(z, w0, wx, wy):
    """A z on the interior of natural padded arrays (numpy, weights broadcast over channels)."""
    zc = z[:, 1:-1, 1:-1]
    out = np.zeros_like(z)
    out[:, 1:-1, 1:-1] = (w0[:, 1:-1, 1:-1] * zc + wx[:, 1:-1, 1:-1] * (zc - z[:, 1:-1, 2:])
                          + wx[:, 1:-1, :-2] * (zc - z[:, 1:-1, :-2])
                          + wy[:, 1:-1, 1:-1] * (zc - z[:, 2:, 1:-1])
                          + wy[:, :-2, 1:-1] * (zc - z[:, :-2, 1:-1]))
    return out


def colour_mask(h, w, colour):
    y, x = np.mgrid[1:h + 1, 1:w + 1]            # padded coordinates of the interior
    return (x + y) % 2 == colour


def ref_sweep(z, b, wx, wy, invd, colour, om):
    """Red-black SOR on natural padded arrays: points of one colour move om x their Gauss-Seidel
    step, computed from the other colour only (so all at once)."""
    h, w = z.shape[1] - 2, z.shape[2] - 2
    zc = z[:, 1:-1, 1:-1]
    t = (b[:, 1:-1, 1:-1] + wx[:, 1:-1, 1:-1] * z[:, 1:-1, 2:]
         + wx[:, 1:-1, :-2] * z[:, 1:-1, :-2] + wy[:, 1:-1, 1:-1] * z[:, 2:, 1:-1]
         + wy[:, :-2, 1:-1] * z[:, :-2, 1:-1]) * invd[:, 1:-1, 1:-1]
    out = z.copy()
    out[:, 1:-1, 1:-1] = np.where(colour_mask(h, w, colour), zc + om * (t - zc), zc)
    return out


def frame_is_zero(s, w):
    """Every slot outside the interior (frame, spare slot of an odd width) holds 0."""
    return np.array_equal(spl(nat(s, w), s.dtype), s)


@pytest.mark.parametrize("h, w", SIZES)
def test_split_layout_round_trip_and_slots(h, w):
    rng = np.random.default_rng(1)
    a = rng.standard_normal((h, w, 3))
    s = to_split(a)
    assert s.shape == split_shape(3, h, w)
    assert np.array_equal(from_split(s, w), a)
    # padded column X lives in half X % 2 at index X // 2
    assert s[2, 1 + h // 2, (1 + w // 2) % 2, (1 + w // 2) // 2] == a[h // 2, w // 2, 2]
    assert frame_is_zero(s, w)


@pytest.mark.parametrize("h, w", SIZES)
@pytest.mark.parametrize("cw", [1, 3])
def test_apply_split_equals_natural_operator(h, w, cw):
    w0, wx, wy, z, _, _ = problem(h, w, cw)
    out_n = np.zeros_like(z)
    pap_n = apply_planar(z, w0, wx, wy, out_n)
    sw = [spl(a) for a in (w0, wx, wy)]
    out_s = np.zeros(split_shape(3, h, w))
    r = np.random.default_rng(7).standard_normal((h, w, 3))
    sums = apply_split(spl(z), *sw, out_s, w, to_split(r))
    # the same products summed in another order: round-off only (values ~1e2 at most)
    assert np.abs(nat(out_s, w) - out_n).max() < 1e-11
    assert np.allclose(sums[0], pap_n, rtol=1e-12, atol=1e-12)
    zi, ai = z[:, 1:-1, 1:-1], out_n[:, 1:-1, 1:-1]
    rk = np.moveaxis(r, 2, 0)
    for got, want in zip(sums[1:], ((rk * zi).sum(axis=(1, 2)), (rk * ai).sum(axis=(1, 2)),
                                    (ai * ai).sum(axis=(1, 2)))):
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12)
    assert frame_is_zero(out_s, w)


@pytest.mark.parametrize("h, w", SIZES)
@pytest.mark.parametrize("cw", [1, 3])
@pytest.mark.parametrize("dtype, tol", [(np.float64, 1e-12), (np.float32, 1e-4)])
def test_rb_sweeps_equal_the_natural_smoother(h, w, cw, dtype, tol):
    """rb_first_pair (the red sweep from z = 0 and the black one after it, fused) then sweeps of
    both colours (as the V-cycle runs them) against ref_sweep; tolerance: float64 round-off, or
    float32 round-off (~1e-7 relative) on values up to ~1e2 after five sweeps."""
    w0, wx, wy, _, b, invd = problem(h, w, cw, seed=2)
    om = 1.2
    zn = ref_sweep(np.zeros_like(b), b, wx, wy, invd, 0, om)       # red from 0
    zn = ref_sweep(zn, b, wx, wy, invd, 1, om)
    sb, swx, swy, sinvd = (spl(a, dtype) for a in (b, wx, wy, invd))
    zs = spl(to_planar(np.full((h, w, 3), 7.0)), dtype)    # stale interior values, zero frame
    mf.rb_first_pair(zs, sb, swx, swy, sinvd, dtype(om), w)    # must not need a zeroed z
    scale = max(1.0, np.abs(zn).max())
    assert np.abs(nat(zs, w) - zn).max() <= tol * scale
    for colour in (1, 0, 1, 0):
        zn = ref_sweep(zn, b, wx, wy, invd, colour, om)
        mk.rb_sweep(zs, sb, swx, swy, sinvd, colour, dtype(om), w)
        scale = max(1.0, np.abs(zn).max())
        assert np.abs(nat(zs, w) - zn).max() <= tol * scale
    assert frame_is_zero(zs, w)


@pytest.mark.parametrize("h, w", SIZES)
@pytest.mark.parametrize("cw", [1, 3])
def test_jacobi_and_inverse_diagonal_equal_numpy(h, w, cw):
    w0, wx, wy, z, b, invd = problem(h, w, cw, seed=3)
    sw = [spl(a) for a in (w0, wx, wy)]
    sinvd = np.zeros(sw[0].shape)
    mk.inverse_diagonal(*sw, sinvd, w)
    assert np.allclose(nat(sinvd, w), invd, rtol=1e-14, atol=0)
    out = np.zeros(split_shape(3, h, w))
    mk.jacobi(spl(z), spl(b), *sw, sinvd, 0.8, out, w)
    want = z + 0.8 * invd * (b - a_times(z, w0, wx, wy))
    assert np.abs(nat(out, w) - want).max() < 1e-11
    assert frame_is_zero(out, w) and frame_is_zero(sinvd, w)


def block_sum(a, hc, wc):
    """P^T a: natural padded fine -> natural padded coarse, 2 x 2 blocks of the interior."""
    c, hp, wp = a.shape
    out = np.zeros((c, hc + 2, wc + 2))
    for yc in range(1, hc + 1):
        for xc in range(1, wc + 1):
            ys = [y for y in (2 * yc - 1, 2 * yc) if y <= hp - 2]
            xs = [x for x in (2 * xc - 1, 2 * xc) if x <= wp - 2]
            out[:, yc, xc] = a[:, ys][:, :, xs].sum(axis=(1, 2))
    return out


@pytest.mark.parametrize("h, w", SIZES)
@pytest.mark.parametrize("cw", [1, 3])
def test_transfers_and_coarsening_equal_numpy(h, w, cw):
    """residual_restrict = P^T (b - A z), prolong_add = z + P ec, coarsen = block sums of w0 and
    half the sum of the two fine edges a coarse edge crosses (multigrid module docstring)."""
    w0, wx, wy, z, b, _ = problem(h, w, cw, seed=4)
    hc, wc = (h + 1) // 2, (w + 1) // 2
    sw = [spl(a) for a in (w0, wx, wy)]
    rc = np.full(split_shape(3, hc, wc), np.nan)       # every slot must be written
    mk.residual_restrict(spl(z), spl(b), *sw, rc, w)
    want = block_sum(b - a_times(z, w0, wx, wy), hc, wc)
    assert np.abs(nat(rc, wc) - want).max() < 1e-11 and frame_is_zero(rc, wc)
    ec = to_planar(np.random.default_rng(5).standard_normal((hc, wc, 3)))
    zs = spl(z)
    mk.prolong_add(zs, spl(ec), w)
    y, x = np.mgrid[0:h + 2, 0:w + 2]
    want = z + np.where((y > 0) & (y <= h) & (x > 0) & (x <= w), ec[:, (y + 1) // 2, (x + 1) // 2],
                        0.0)
    assert np.abs(nat(zs, w) - want).max() < 1e-14 and frame_is_zero(zs, w)
    cl = [np.full(split_shape(cw, hc, wc), np.nan) for _ in range(3)]
    mk.coarsen(*sw, 0.5, *cl, w)
    ys, xs = 2 * np.arange(1, hc + 1) - 1, 2 * np.arange(1, wc + 1) - 1
    pad_y, pad_x = np.zeros((cw, 1, w + 2)), np.zeros((cw, h + 3, 1))
    f0, fx, fy = (np.concatenate([np.concatenate([a, pad_y], 1), pad_x], 2) for a in (w0, wx, wy))
    c0 = (f0[:, ys][:, :, xs] + f0[:, ys][:, :, xs + 1] + f0[:, ys + 1][:, :, xs]
          + f0[:, ys + 1][:, :, xs + 1])
    cx = 0.5 * (fx[:, ys][:, :, xs + 1] + fx[:, ys + 1][:, :, xs + 1])
    cy = 0.5 * (fy[:, ys + 1][:, :, xs] + fy[:, ys + 1][:, :, xs + 1])
    for got, want in zip(cl, (c0, cx, cy)):
        assert np.abs(nat(got, wc)[:, 1:-1, 1:-1] - want).max() < 1e-13
        assert frame_is_zero(got, wc)


@pytest.mark.parametrize("h, w", SIZES + [(40, 9), (41, 16), (2, 3)])
@pytest.mark.parametrize("cw", [1, 3])
@pytest.mark.parametrize("dtype, tol", [(np.float64, 1e-12), (np.float32, 1e-5)])
@pytest.mark.parametrize("parallel", [False, True])
def test_presmooth_restrict_equals_sweep_then_restrict(h, w, cw, dtype, tol, parallel):
    """The fused pre-smoothing + restriction (one pass, halo rows recomputed per chunk, the
    residual without a diagonal product) against rb_first_pair then residual_restrict, serial
    and parallel twins (the parallel one's chunks of coarse rows start at every other fine row,
    so halos are exercised). Tolerance: round-off of the two formulas (D z = om b holds up to
    the rounding of 1 / D), relative to the largest residual."""
    w0, wx, wy, _, b, invd = problem(h, w, cw, seed=8)
    hc, wc = (h + 1) // 2, (w + 1) // 2
    sb, sw0, swx, swy, sinvd = (spl(a, dtype) for a in (b, w0, wx, wy, invd))
    om = dtype(1.2)
    z_ref = np.zeros(sb.shape, dtype)
    mf.rb_first_pair(z_ref, sb, swx, swy, sinvd, om, w)
    rc_ref = np.zeros(split_shape(3, hc, wc), dtype)
    mk.residual_restrict(z_ref, sb, sw0, swx, swy, rc_ref, w)
    z = spl(to_planar(np.full((h, w, 3), 7.0)), dtype)     # stale interior, zero frame
    rc = np.full(split_shape(3, hc, wc), np.nan, dtype)    # every slot must be written
    fused = mf.presmooth_restrict.parallel if parallel else mf.presmooth_restrict.serial
    fused(z, sb, swx, swy, sinvd, om, rc, w)
    assert np.abs(z - z_ref).max() <= tol * max(1.0, np.abs(z_ref).max())
    assert np.abs(rc - rc_ref).max() <= tol * max(1.0, np.abs(rc_ref).max())
    assert frame_is_zero(z, w) and frame_is_zero(rc, wc)


@pytest.mark.parametrize("h, w", [(40, 9), (41, 16), (7, 9)])
@pytest.mark.parametrize("nch", [3, 5])
def test_presmooth_restrict_chunks_need_no_other_chunk(h, w, nch):
    """Each chunk of presmooth_restrict must read only what no other chunk writes (its halo rows
    recomputed): run the chunks one by one in reverse order, on a z whose rows are NaN until a
    chunk writes them, and every chunk must still give the reference rows (in forward order a
    chunk that read its upper neighbour's rows of z would get them right by luck; in reverse
    order the NaN of the unwritten rows shows). Float64: round-off only."""
    _, wx, wy, _, b, invd = problem(h, w, 1, seed=11)
    hc, wc = (h + 1) // 2, (w + 1) // 2
    sb, swx, swy, sinvd = (spl(a) for a in (b, wx, wy, invd))
    z_ref = np.zeros(sb.shape)
    rc_ref = np.zeros(split_shape(3, hc, wc))
    mf.presmooth_restrict.serial(z_ref, sb, swx, swy, sinvd, 1.2, rc_ref, w)
    z = spl(to_planar(np.full((h, w, 3), np.nan)))             # NaN interior, zero frame
    rc = np.full(split_shape(3, hc, wc), np.nan)
    for j in reversed(range(nch)):
        mf._presmooth_restrict_chunk(j, nch, z, sb, swx, swy, sinvd, 1.2, rc, w)
    assert np.abs(z - z_ref).max() <= 1e-12 * np.abs(z_ref).max()
    assert np.abs(rc - rc_ref).max() <= 1e-12 * np.abs(rc_ref).max()
