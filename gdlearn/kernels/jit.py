"""The numba recipe, written down once: every compiled function outside :mod:`gdlearn.reconstruct`
is declared with one of these decorators (reconstruct, which imports nothing else from gdlearn,
has its own ``reconstruct._jit.kernel``).

All of them share three choices:

* ``cache=True``: compiled code is kept on disk, keyed by the hash of gdlearn's sources
  (:func:`gdlearn.source_hash`), so a process pays the JIT once per edit, not once per run --
  closures over compiled functions too (:class:`_ClosureCache`; numba's own key missed them in
  every new process: 14.9 s of G-VPM's full image on the fog box, 1.2 s now).
* ``error_model="numpy"``: a division by zero gives inf/NaN instead of raising. Compiled code
  cannot recover from an exception in the middle of a render, while a non-finite value is caught
  where it arises (a zero pdf, a grazing Jacobian) or, at the latest, by the row drivers, which
  drop and count the sample: NaN or Inf never reach an image. (The python model also costs a
  branch per division.)
* float64 everywhere, no jitclass, no mutable globals (numba freezes globals at compile time).

What differs is how a function is called:

========================  =======================================================================
decorator                 use it for
========================  =======================================================================
:func:`block`             a building block called from other compiled code, not inlined (BVH
                          builds, set-up helpers, functions that allocate).
:func:`inlined`           a small hot helper LLVM should inline into its caller (``forceinline``):
                          a non-inlined call passes every tuple and array as dozens of scalars.
:func:`leaf`              a hot helper that allocates nothing: inlined *and* compiled without
                          numba's reference counting (``_nrt=False``). Reference counts on the
                          scene's array views were the largest cost of the path kernels; numba
                          refuses ``np.empty`` in such a function, which is the point.
:func:`noalloc`           as :func:`leaf` but not inlined: a large allocation-free function (a
                          whole path's radiance) that several kernels call. A call passes every
                          array as scalars (the scene: over a hundred), so not for a step run
                          per vertex: gpt's passes in media were 20-30 % slower with its flights
                          and next event as noalloc calls.
:func:`ir_inline`         numba-IR inlining (``inline="always"``): for functions whose arguments
                          are typed per call site (a tuple of arrays of varying layout) or that
                          return small tuples the caller unpacks; and for a large function with one
                          call site whose caller is itself inlined or compiled whole (a row of the
                          packet tracers, a lane's surface or medium vertex), to shorten the cold
                          compile (below).
:func:`rows`              a parallel row driver (``parallel=True``, ``prange`` over rows): each
                          row writes only its own pixels or a private buffer. A large kernel can
                          instead be a ``block(nogil=True)`` driver run on threads by
                          :func:`gdlearn.kernels.threads.run_rows` (gpt's: a third less to compile).
========================  =======================================================================

In a :func:`rows` loop, write ``for row in prange(h): y = np.int64(row)``: numba types the prange
index as int64 while it infers the loop's types and as uint64 when it lowers the parallel body, so
every non-inlined function that receives the raw index is compiled twice (the whole gpt sample
function and everything under it: ~20 s of a cold compile).

Why IR inlining shortens a cold compile: numba compiles every function it does not IR-inline into a
library of its own -- typed, optimised and turned into machine code -- and a caller links its
callees' code in and optimises and emits it again. A helper called once inside a packet's vertex is
thus compiled at every level above it; IR-inlined, once. The packet tracers' rows and vertices
are IR-inlined (pt's cold compile, fog box 22.3 -> 20.4 s, Cornell box 20.8 -> 17.6 s), and so are
the one-call-site steps of gpt's volume sample (44.9 -> 40.2 s on the volume caustic, its pass
unchanged). LLVM optimises the bigger function differently, though, so measure the warm pass too:
the fog box's pass was 13 % slower with the packet's ``_shade`` IR-inlined into its lane loop, and
gpt's surface pass 7-10 % slower with its next-event and offset-start steps IR-inlined; those stay
leaves.

The same holds one level up: a large non-inlined function with one caller is compiled twice, in
its own library and in its caller's. gpt's per-sample functions (``gpt_sample``,
``gpt_volume_sample``) and the packet tracers' chunk loops (``trace_items``, ``trace_items_volume``)
are therefore IR-inlined into their row drivers, and compiled once: their own libraries had taken
6-12 s (gpt) and ~2.5 s (pt) of a cold compile, and the passes did not get slower. Not every
one-caller function gains: IR-inlining gpt's per-vertex shift step (``_shift_offsets``) cost the
surface passes 3-5 %, and the volume's ``shift_free_mixed`` 20-30 % (benchmarks/README.md,
"Compiled once").

The photon passes' camera kernels (G-VPM, G-BRE, the surface pass of their full images, VPM and the
BRE) are row drivers on threads whose per-row and per-photon steps are IR-inlined: G-BRE's cold
compile went from 372 to 123 s, G-VPM's from 388 to 120 s, and G-BRE's pass got faster
(benchmarks/README.md, "G-VPM's and G-BRE's cold compile"). One rule comes with it: numba releases an array after its *last use*,
not at the end of the function, so an IR-inlined function must not borrow views
(:func:`gdlearn.kernels.arrays.borrow`) of scratch its caller allocated and then stop using -- the
owner is freed under the views, and another thread's rows reuse the memory. The function that
borrows a row's scratch stays a call of its own, so the owners live until it returns
(``gbre_gather._pixels``).

Copy arrays with loops, not slice assignments (``a[:k] = b[:k]``, ``X[:] = Y``): each one compiles
numba's shape check, whose error message is built with f-strings and ``str.join``, in every
specialisation around it. Filling with a scalar (``a[:] = 0.0``) has no shape to check. gpt's volume
rows lost 43 compiled functions that way, and G-VPM's manifold walk 48 and ~25 s of its cold
compile (benchmarks/README.md, "One leaf, compiled as one leaf" and "The manifold walk's copies").

Each decorator works bare (``@leaf``) and with extra numba options (``@block(fastmath=True)``).
"""
from __future__ import annotations

import hashlib
import os

from numba.core import types
from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher
from numba.core.registry import CPUDispatcher
from numba.core.serialize import dumps

_BASE = dict(error_model="numpy", nopython=True, boundscheck=None)


class _Dispatcher(CPUDispatcher):
    """numba's dispatcher, typed for the *non-literal* types of its arguments when called from compiled
    code. numba's own compiles one specialisation per constant at a call site (``get3(of, k, F_POS)``
    and ``get3(of, k, F_WI)`` are two functions, ``dim(depth, D_LOBE)`` one per dimension): a cold
    compile of gpt typed and optimised ~30 such copies. The callee is inlined by LLVM (or small), so
    the constants are still folded where it matters."""

    def get_call_template(self, args, kws):
        args = tuple(types.unliteral(a) for a in args)
        kws = {k: types.unliteral(v) for k, v in kws.items()}
        return super().get_call_template(args, kws)


def _stable(obj):
    """What a closure cell holds, in a form whose pickle is the same in every process: a compiled
    function by its name, its bytecode and its file's stamp (what numba re-validates a cached
    function by), everything else as it is."""
    if not isinstance(obj, Dispatcher):
        return obj
    fn = obj.py_func
    try:
        st = os.stat(fn.__code__.co_filename)
        stamp = (st.st_mtime_ns, st.st_size)
    except OSError:
        stamp = None
    cells = tuple(_stable(c.cell_contents) for c in fn.__closure__ or ())
    return (fn.__module__, fn.__qualname__, hashlib.sha256(fn.__code__.co_code).hexdigest(), stamp, cells)


class _ClosureCache(FunctionCache):
    """numba's on-disk cache, with closures over compiled functions found again by a new process.

    numba keys a closure's cached code by the pickle of its cells, and a dispatcher pickles with a
    uuid drawn per process: a kernel made by a factory (``gpm_gather.threaded_rows``,
    ``photon_shift_loop.make_shift_photons``) missed the cache in every process and was compiled
    again -- GPM's and the volume estimators' camera passes, each time a chapter or a command started.
    Here a compiled function in a cell counts by :func:`_stable`'s identity."""

    def _index_key(self, sig, codegen):
        if self._py_func.__closure__ is None:
            return super()._index_key(sig, codegen)
        # numba's key (signature, target, hashes of the bytecode and of the cells), its cells stable;
        # not through super(): that would pickle every captured dispatcher first, only to be replaced
        cells = tuple(_stable(c.cell_contents) for c in self._py_func.__closure__)
        code = hashlib.sha256(self._py_func.__code__.co_code).hexdigest()
        return (sig, codegen.magic_tuple(), (code, hashlib.sha256(dumps(cells)).hexdigest()))


def _compile(fn, opts):
    disp = _Dispatcher(py_func=fn, locals={}, targetoptions=opts)
    disp._cache = _ClosureCache(fn)            # cache=True (numba's enable_caching, closures keyed stably)
    return disp


def _recipe(**options):
    def decorator(fn=None, **extra):
        opts = {**_BASE, **options, **extra}
        if fn is None:
            return lambda f: _compile(f, opts)
        return _compile(fn, opts)
    return decorator


block = _recipe()
inlined = _recipe(forceinline=True)
#: :func:`inlined`'s options, for an ``overload`` whose body numba picks by argument type
INLINED_OPTIONS = dict({k: v for k, v in _BASE.items() if k != "nopython"}, forceinline=True)
leaf = _recipe(forceinline=True, _nrt=False)
#: :func:`leaf`'s options, for an ``overload`` whose body numba picks by argument type
LEAF_OPTIONS = dict(INLINED_OPTIONS, _nrt=False)
noalloc = _recipe(_nrt=False)
ir_inline = _recipe(inline="always")
rows = _recipe(parallel=True)

__all__ = ["INLINED_OPTIONS", "LEAF_OPTIONS", "block", "inlined", "leaf", "noalloc", "ir_inline", "rows"]
