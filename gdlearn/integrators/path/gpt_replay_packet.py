"""gpt-replay's sampling loop on the packet tracer: Algorithm 1 of Hua et al. 2019 (the STAR,
Sec. 2.3) for the scenes :func:`gdlearn.integrators.path.packet.eligible` accepts, and with media
for those :func:`gdlearn.integrators.path.packet_volume.eligible` accepts.

The one-path kernel (:func:`gdlearn.integrators.path.gpt_replay.replay_rows_path`) traces, per
sample, the base path and then its surviving offsets, one path at a time. Here a row's samples go
through the packet tracer in two waves per chunk: first the base paths (``pt``'s items), then the
offsets of those bases -- film position moved by one pixel, the base pixel's key and sample
(:mod:`gdlearn.shifts.replay`) -- that survive the shift roulette, which needs the base's value
(:func:`gdlearn.shifts.replay.shift_q`, the same random numbers). Every path is the packet
tracer's, so ``radiance_path``'s (``radiance_volpath``'s) bit for bit, and every sum runs over the
samples in their order: the five buffers and the counters equal the one-path kernel's exactly
(tests/test_gpt_replay_packet.py).
"""
import numpy as np

from gdlearn.integrators.path.accumulate import store_means
from gdlearn.integrators.path import packet_volume
from gdlearn.integrators.path.packet import fill_pixel_items, trace_items
from gdlearn.integrators.path.packet_rows import IT_FX, IT_FY, IT_KEY, IT_S, N_ITEMS, new_buffers
from gdlearn.integrators.path.packet_volume import trace_items_volume
from gdlearn.kernels.accel.bvh import STACK_SIZE
from gdlearn.kernels.arrays import borrowed
from gdlearn.kernels.jit import block, ir_inline, leaf, noalloc
from gdlearn.kernels.threads import next_rows, run_rows
from gdlearn.shifts.replay import offset_film_position, shift_q

#: base samples per chunk: their up to four offsets each fill the offset table
CHUNK = N_ITEMS // 4


def replay_rows_packet(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold, rr_min,
                       out, counts, diag, want_diag):
    """:func:`gdlearn.integrators.path.gpt_replay.replay_rows_path`'s buffers and counters, traced in
    packets on threads (``want_diag`` is not supported: the caller uses the one-path kernel)."""
    run_rows(lambda counter, step: _rows(sa, seed, sample0, spp, max_depth, rr_depth, rr_threshold, rr_min, out,
                                         counts, counter, step, True, None), out.shape[1])


def replay_rows_packet_volume(sa, seed, sample0, spp, max_depth, rr_depth, mask, threshold, rr_threshold, rr_min,
                              out, counts, diag, want_diag):
    """As :func:`replay_rows_packet` with media: :func:`gdlearn.integrators.path.gpt_replay.replay_rows_volpath`'s
    buffers and counters."""
    run_rows(lambda counter, step: _rows(sa, seed, sample0, spp, max_depth, rr_depth, rr_threshold, rr_min, out,
                                         counts, counter, step, None, True), out.shape[1])


@block(nogil=True)
def _rows(sa, seed, sample0, spp, max_depth, rr_depth, rr_threshold, rr_min, out, counts, counter, step, surface,
          volume):
    """(surface, volume) = (True, None): the surface tracer; (None, True): the volume tracer. numba
    prunes a branch before typing only where it tests a *None* argument (True is an unknown bool),
    so each tracer hides behind ``if its_flag is not None`` and each kernel holds one tracer."""
    sa = borrowed(sa)
    h, w = out.shape[1], out.shape[2]
    stack = np.empty(STACK_SIZE, dtype=np.int32)
    S, Q, buf, items = new_buffers()
    if volume is not None:
        S, Q = packet_volume.new_buffers()
    obuf, oitems = np.zeros(3 * N_ITEMS), np.zeros((N_ITEMS, 4))
    oref = np.zeros((N_ITEMS, 2), dtype=np.int64)          # an offset's base item and shift k
    oq = np.zeros(N_ITEMS)                                  # its survival probability
    acc = np.zeros((w, 5, 3))
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            _row(sa, y, seed, sample0, spp, max_depth, rr_depth, rr_threshold, rr_min, out, counts[y], S, Q, buf,
                 items, obuf, oitems, oref, oq, acc, stack, surface, volume)


# a call of its own: the row calls it twice (bases, offsets), and the packet loops are IR-inlined here
@noalloc
def _trace(sa, items, m, seed, max_depth, rr_depth, S, Q, buf, stack, surface, volume):
    if surface is not None:
        trace_items(sa, items, m, seed, max_depth, rr_depth, S, Q, buf, stack)
    if volume is not None:
        trace_items_volume(sa, items, m, seed, max_depth, rr_depth, S, Q, buf, stack)


@leaf
def _finite(buf, i):
    return np.isfinite(buf[3 * i]) and np.isfinite(buf[3 * i + 1]) and np.isfinite(buf[3 * i + 2])


@leaf
def _offsets(items, m, i0, y, w, h, spp, seed, buf, rr_threshold, rr_min, cnt, acc, oitems, oref, oq):
    """The bases' sums, and the table of the offsets that are traced (returns their number)."""
    no = 0
    for i in range(m):
        if not _finite(buf, i):
            cnt[3] += 1
            continue
        x = (i0 + i) // spp
        key, s = np.int64(items[i, IT_KEY]), np.int64(items[i, IT_S])
        base = (buf[3 * i], buf[3 * i + 1], buf[3 * i + 2])
        for c in range(3):
            acc[x, 0, c] += base[c] * 1.0
        for k in range(4):
            q = shift_q(x, y, k, w, h, base, seed, key, s, rr_threshold, rr_min, cnt)
            if q == 0.0:
                continue
            oitems[no, IT_FX], oitems[no, IT_FY] = offset_film_position(items[i, IT_FX], items[i, IT_FY], k)
            oitems[no, IT_KEY], oitems[no, IT_S] = key, s        # same key: the base's numbers (Eq. 6-7)
            oref[no, 0], oref[no, 1] = i, k
            oq[no] = q
            no += 1
    return no


@ir_inline
def _row(sa, y, seed, sample0, spp, max_depth, rr_depth, rr_threshold, rr_min, out, cnt, S, Q, buf, items, obuf,
         oitems, oref, oq, acc, stack, surface, volume):
    h, w = out.shape[1], out.shape[2]
    n = w * spp
    acc[:, :, :] = 0.0
    for i0 in range(0, n, CHUNK):
        m = min(CHUNK, n - i0)
        fill_pixel_items(items, i0, m, y, w, spp, seed, sample0)
        _trace(sa, items, m, seed, max_depth, rr_depth, S, Q, buf, stack, surface, volume)
        no = _offsets(items, m, i0, y, w, h, spp, seed, buf, rr_threshold, rr_min, cnt, acc, oitems, oref, oq)
        _trace(sa, oitems, no, seed, max_depth, rr_depth, S, Q, obuf, stack, surface, volume)
        for r in range(no):
            if not _finite(obuf, r):
                cnt[3] += 1
                continue
            cnt[0] += 1
            i, k = oref[r, 0], oref[r, 1]
            x = (i0 + i) // spp
            scale = 1.0 / oq[r]
            for c in range(3):
                acc[x, 1 + k, c] += (obuf[3 * r + c] - buf[3 * i + c]) * scale
    inv = 1.0 / spp
    for x in range(w):
        store_means(out, y, x, acc[x], inv)
