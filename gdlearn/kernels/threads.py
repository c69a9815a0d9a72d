"""Rows on threads without a parallel kernel: :func:`run_rows` and its atomic row counter.

numba's ``parallel=True`` turns a ``prange`` loop into a separate *gufunc* that it types and
optimises on its own, with everything inlined into it, after the function around it -- one more
pass of the optimiser over the whole kernel. For gpt's kernels that pass was about a third of a
cold compile (benchmarks/README.md). A row driver that is an ordinary compiled function instead,
compiled with ``nogil=True`` and called from a few Python threads at once, runs the same rows in
parallel at the compile cost of a serial function.

Each thread calls the driver once; the driver takes the next chunk of rows from a shared counter
with an atomic fetch-and-add (:func:`next_rows`) until the image is done, so rows are dealt out
dynamically as ``prange`` with a chunk size does (rows differ in cost: the light, the boxes,
escaping rays), and the threads cross into Python only to start and to finish.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from gdlearn.kernels.jit import inlined

#: chunks per image: small enough that no thread idles long at the end of a pass, large enough
#: that the counter is touched rarely (the value ``SceneSetup.parallel`` gives ``prange``)
CHUNKS = 32


@intrinsic
def fetch_add(typingctx, counter, value):
    """Atomically add ``value`` to ``counter[0]`` (a 1-D int64 array) and return the old value."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64 and counter.ndim == 1
            and isinstance(value, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        arr = context.make_array(counter)(context, builder, value=args[0])
        v = context.cast(builder, args[1], signature.args[1], types.int64)
        return builder.atomic_rmw("add", arr.data, v, "seq_cst")

    return types.int64(counter, value), codegen


@inlined
def next_rows(counter, step, rows):
    """The next chunk ``(y0, y1)`` of at most ``step`` rows a driver renders, ``y0 == y1`` once the
    image is done. A driver's loop::

        while True:
            y0, y1 = next_rows(counter, step, h)
            if y0 == y1:
                return
            for y in range(y0, y1): ...
    """
    y0 = min(fetch_add(counter, step), rows)
    return y0, min(y0 + step, rows)


_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    """One pool for the process, started on first use: starting threads for every pass cost ~0.2 ms,
    a few per cent of a small pass."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=max(1, numba.config.NUMBA_NUM_THREADS - 1),
                                   thread_name_prefix="gdlearn-rows")
    return _POOL


def run_rows(worker, rows: int, threads: int | None = None) -> None:
    """Run ``worker(counter, step)`` on ``threads`` threads at once (default: numba's thread count,
    which :meth:`gdlearn.integrators.setup.SceneSetup.parallel` sets) and wait for all of them.

    ``worker`` is a compiled ``nogil`` row driver: it renders the chunks :func:`next_rows` hands out
    until the image is done. The calling thread is one of the
    threads; the others come from a pool kept for the process. An exception in any of them is
    raised here, after all have stopped."""
    n = max(1, min(int(threads or numba.get_num_threads()), rows))
    counter = np.zeros(1, dtype=np.int64)
    step = max(1, rows // CHUNKS)
    others = [_pool().submit(worker, counter, step) for _ in range(n - 1)]
    try:
        worker(counter, step)
    finally:
        for f in others:
            f.exception()                 # wait for every thread before the buffers are read
    for f in others:
        f.result()


__all__ = ["CHUNKS", "fetch_add", "next_rows", "run_rows"]
