"""``kernel``: compile a row-parallel numba stencil twice -- parallel for large images, serial for
small ones.

A ``parallel=True`` kernel pays a thread-pool launch per call (tens of microseconds when idle,
milliseconds on a busy machine); conjugate gradients on a 13 x 9 test image makes thousands of
calls, each touching a few hundred values. The serial twin (same source, ``prange`` acting as
``range``) removes that overhead; results are identical up to the order of floating-point sums.
Both twins use ``cache=True`` under distinct names, so their on-disk caches never collide.
"""
from __future__ import annotations

import functools
import types

from numba import njit

#: Arrays with at least this many values (~300 x 300 x 3) use the parallel twin.
PARALLEL_MIN_SIZE = 1 << 18


def kernel(fn=None, *, fastmath=False, error_model="python"):
    """Decorator: ``fn(*arrays)`` dispatches on the size of its first argument.

    ``@kernel(fastmath=True)`` lets LLVM reassociate float sums, so loops with a reduction
    (inner products) vectorise; only for kernels whose inputs are finite by construction and whose
    results may differ from a sequential sum by round-off. ``error_model="numpy"``: a float
    division by zero gives inf / nan instead of raising ZeroDivisionError -- numba's default
    test before every division keeps a loop with a division scalar; only for kernels whose
    divisions are guarded (``1 / d if d > 0``, ``1 + e / eps`` with eps > 0).
    """
    if fn is None:
        return functools.partial(kernel, fastmath=fastmath, error_model=error_model)
    par = njit(cache=True, parallel=True, fastmath=fastmath, error_model=error_model)(fn)
    twin = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_serial",
                              fn.__defaults__, fn.__closure__)
    twin.__qualname__ = fn.__qualname__ + "_serial"
    twin.__module__ = fn.__module__
    ser = njit(cache=True, fastmath=fastmath, error_model=error_model)(twin)

    @functools.wraps(fn)
    def call(*args):
        return (par if args[0].size >= PARALLEL_MIN_SIZE else ser)(*args)

    call.parallel = par
    call.serial = ser
    return call
