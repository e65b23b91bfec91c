"""Numba plumbing shared by the kernels of every layer."""
from __future__ import annotations

import types

from numba import njit

# numba fast-math flags that keep every rounding of a kernel: finite values assumed (no
# NaN or infinity tests kept), signed zeros and reciprocals free, but no reassociation and
# no contraction into fused multiply-adds, so a sum comes out bit for bit as written (the
# condensed 3D viscous block stays exactly symmetric). The row kernel of that block took
# 1.08 s against 1.54 s with them at 30,000 nodes; full fast-math took 1.19 s and broke
# the symmetry. Only for kernels whose inputs are checked finite before.
EXACT_FASTMATH = {"nnan", "ninf", "nsz", "arcp"}     # (numba takes a set, not a frozenset)


def serial_twin(kernel, **options):
    """A one-thread copy of the parallel numba kernel ``kernel`` (its
    ``prange`` loops run as plain loops), with a cache entry of its own.

    On small batches waking the thread pool costs more than the work, so
    callers pick the twin there. ``njit(cache=True)(kernel.py_func)`` would
    not do: numba names a function's cache file after its module, qualified
    name and first line, and keys the entries by signature only, so the
    serial and the parallel compilation would serve each other from one
    entry (whichever compiled first wins). The twin is the same code under
    the qualified name ``<name>_serial``. ``options`` go to ``njit``.
    """
    f = getattr(kernel, "py_func", None)
    if f is None:  # NUMBA_DISABLE_JIT=1 (debugging in Python): the kernel is plain Python
        return kernel
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_serial",
                           f.__defaults__, f.__closure__)
    g.__qualname__ = f.__qualname__ + "_serial"
    g.__module__ = f.__module__
    g.__doc__ = f.__doc__
    g.__kwdefaults__ = f.__kwdefaults__
    return njit(cache=True, **options)(g)


@njit(cache=True, inline="always")
def sort_with(keys, carry, cnt):
    """Insertion sort of ``keys[:cnt]`` in place, ``carry[:cnt]`` moved along (rows of
    tens: a node's entries of a coordinate row, a stencil)."""
    for a in range(1, cnt):
        k, c = keys[a], carry[a]
        b = a - 1
        while b >= 0 and keys[b] > k:
            keys[b + 1], carry[b + 1] = keys[b], carry[b]
            b -= 1
        keys[b + 1], carry[b + 1] = k, c
