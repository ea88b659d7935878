"""Compiled kernels of the robot-side hot paths: numba, set up once.

``kernel`` is ``numba.njit`` with the settings every kernel of the stack uses:

- ``cache=True``: the machine code is written next to the module (``__pycache__``) and loaded by the next process
  (a bench worker, a test run) instead of compiled again. Where that folder is read-only (an installed wheel in a
  system location) numba writes to ``$NUMBA_CACHE_DIR`` if set, else to the user's cache folder
  (``~/.cache/numba``); if no folder is writable at all, the kernels are compiled in memory at their first call in
  each process (no error).
- no ``fastmath``, no ``parallel``: IEEE arithmetic in program order, one thread, so a kernel gives the same bits
  in every process on a machine, whatever the memory layout of its inputs (no reassociated or alignment-dependent
  vector reductions, no fused multiply-adds, which LLVM does not form without fast-math flags).
- ``error_model="numpy"``: a division by zero gives inf/nan as in numpy instead of raising (the kernels guard their
  divisions; this only removes the checks from the loops).
"""
from __future__ import annotations

import numba


def kernel(fn):
    """``numba.njit(cache=True, error_model="numpy")``, without the cache where no cache folder is writable."""
    try:
        return numba.njit(cache=True, error_model="numpy")(fn)
    except RuntimeError:           # numba: "cannot cache function ...: no locator available"
        return numba.njit(error_model="numpy")(fn)
