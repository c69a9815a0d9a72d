"""The ``replay`` policy of ``gpt``: random-sequence replay of the *whole* path (STAR, Hua et al. 2019,
Sec. 3.1, Eq. 6-7), with Eq. 17's weights, which are exactly 1/2 under replay.

Why not the lockstep loop of :mod:`gdlearn.integrators.path.gpt_surface.lockstep`. The lockstep loop pairs every base
technique (an emitter hit or a next-event sample at some depth) with the offset's technique of the
same depth, and a pair needs a partner: where the offset's vertex is of another kind (connectable
vs not, delta-only vs not), where it escaped while the base did not, or where the base stopped
while the offset could go on, the pair is declared failed (weight 1, offset 0, STAR Sec. 3.5). The
reconnection policies need that rule -- the reverse shift must choose the same action -- but replay
does not: its shift is the identity in primary sample space, reversible for any vertex kinds and
any path lengths, and its offset contribution is simply what the path tracer returns for the same
random numbers at the neighbouring film position (Eq. 7). Declaring those pairs failed turned a
weight-1/2 sum of two correlated estimates into a weight-1 finite difference: measured 0.07-0.23
failed steps per path, and 0.66-0.82x the gradient error ratio of ``gpt-replay``.

So here every offset is the primal tracer's full path (``surface_path.radiance_path`` or
``volume_path.radiance_volpath``) with the base pixel's key, and per shift k

    D_k = w (F_q - F_p),   S_k = w F_q,   w = 1/2 (Eq. 17 with |J| = p(x) / p(x'), Eq. 6),

which is ``gpt-replay``'s estimator without its shift roulette. The forward and backward shift of
one pair both get 1/2, so ``gpt.combine`` sums them with weights (1, 1) as for the other policies.
Stats: one ``replay`` shift per offset path traced (it cannot fail).
"""


from gdlearn.kernels.camera import camera_ray
from gdlearn.integrators.path.gpt_surface.vertex import BROKEN_MIS, BROKEN_PRIMAL
from gdlearn.integrators.path.surface import radiance_path
from gdlearn.integrators.path.volume import radiance_volpath
from gdlearn.shifts.policy import SHIFT_REPLAY, record
from gdlearn.shifts.replay import neighbour_inside, offset_film_position
from gdlearn.kernels.jit import noalloc

#: Eq. 17 under replay: the Jacobian p(x) / p(x') cancels the offset density, both weights are 1/2
REPLAY_WEIGHT = 0.5


@noalloc
def _radiance(sa, volume, fx, fy, rng, cfg, stack):
    seed, key, s = rng.seed, rng.key, rng.s
    o, d, tmax = camera_ray(sa.camera, fx, fy)
    if volume:
        return radiance_volpath(sa, o, d, tmax, seed, key, s, cfg.max_depth, cfg.rr_depth, cfg.mask, cfg.threshold, stack)
    return radiance_path(sa, o, d, tmax, seed, key, s, cfg.max_depth, cfg.rr_depth, cfg.mask, cfg.threshold, stack)


@noalloc
def replay_sample(sa, volume, px, rng, cfg, diff, stats, stack):
    """One base path through film point (fx, fy) of pixel (x, y) (``px``:
    :class:`~gdlearn.integrators.path.params.Pixel`, random numbers ``rng``: ``PathRng``) and its four
    replayed offsets (module docstring); ``diff`` (8, 3) as :func:`gdlearn.integrators.path.gpt_surface.lockstep.gpt_sample`'s: [k] D_k, [4 + k] S_k.
    Returns the base radiance. ``volume``: trace with ``volpath`` (media, null interfaces)."""
    fx, fy, x, y, w, h = px.fx, px.fy, px.x, px.y, px.w, px.h
    diff[:] = 0.0
    base = _radiance(sa, volume, fx, fy, rng, cfg, stack)
    wd = 1.0 if cfg.broken == BROKEN_MIS else REPLAY_WEIGHT
    ws = 1.0 if cfg.broken == BROKEN_PRIMAL else wd
    for k in range(4):
        if not neighbour_inside(x, y, k, w, h):
            continue
        ox, oy = offset_film_position(fx, fy, k)
        # the same key: the base pixel's random numbers, replayed through the neighbour (Eq. 6-7)
        off = _radiance(sa, volume, ox, oy, rng, cfg, stack)
        record(stats, SHIFT_REPLAY, True)
        for c in range(3):
            diff[k, c] = wd * (off[c] - base[c])
            diff[4 + k, c] = ws * off[c]
    return base
