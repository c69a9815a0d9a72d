"""The thread row driver (kernels.threads): every row exactly once, the counter atomic, errors raised.

gpt's kernels run their rows through :func:`run_rows` instead of a ``prange`` kernel (a third less
to compile); a lost or doubled chunk would silently drop or double-count pixels of a pass, so the
row coverage is checked on images whose row count is not a multiple of the chunk, with one and two
threads, and the atomic add under contention and in the emitted code.
"""
import numba
import numpy as np
import pytest

from gdlearn.kernels.jit import block
from gdlearn.kernels.threads import CHUNKS, fetch_add, next_rows, run_rows


@block(nogil=True)
def _mark_rows(visits, counter, step):
    h = visits.shape[0]
    while True:
        y0, y1 = next_rows(counter, step, h)
        if y0 == y1:
            return
        for y in range(y0, y1):
            visits[y] += 1


@block(nogil=True)
def _hammer(total, n, counter, step):
    for _ in range(n):
        fetch_add(total, 1)


@pytest.mark.parametrize("rows", [1, 7, CHUNKS, 3 * CHUNKS + 5, 1001])
@pytest.mark.parametrize("threads", [1, 2])
def test_every_row_is_rendered_once(rows, threads):
    visits = np.zeros(rows, dtype=np.int64)
    run_rows(lambda counter, step: _mark_rows(visits, counter, step), rows, threads)
    np.testing.assert_array_equal(visits, 1)


def test_fetch_add_is_atomic_under_contention():
    total = np.zeros(1, dtype=np.int64)
    n = 1_000_000
    run_rows(lambda counter, step: _hammer(total, n, counter, step), rows=64, threads=2)
    assert total[0] == 2 * n          # every increment of both threads counted
    # a lost update is a matter of timing, so also check the instruction itself: LLVM folds a plain
    # read-add-write loop into one add (no contention left to lose anything), never an atomic one
    fresh = numba.njit(nogil=True)(_hammer.py_func)      # not from the cache: cached code has no IR
    fresh(total, 1, np.zeros(1, dtype=np.int64), 1)
    assert "atomicrmw add" in "".join(fresh.inspect_llvm().values())


def test_fetch_add_returns_the_old_value():
    c = np.array([5], dtype=np.int64)

    @block
    def two(c):
        return fetch_add(c, 3), fetch_add(c, np.int32(2))

    assert two(c) == (5, 8) and c[0] == 10


def test_an_error_in_a_thread_is_raised():
    def worker(counter, step):
        raise RuntimeError("row failed")

    with pytest.raises(RuntimeError, match="row failed"):
        run_rows(worker, rows=16, threads=2)
