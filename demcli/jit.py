"""The one numba wrapper every kernel uses.

Cache policy: on unless ``DEMCLI_NUMBA_CACHE=0``. Threading layer: OpenMP, set
explicitly before any parallel kernel compiles (numba's default picks TBB where it
is installed, which scales poorly for these loops). ``NUMBA_DISABLE_JIT=1`` runs the
kernels as Python for coverage.
"""

import os

import numba

_CACHE = os.environ.get("DEMCLI_NUMBA_CACHE", "1") != "0"

if os.environ.get("NUMBA_THREADING_LAYER") is None:
    numba.config.THREADING_LAYER = "omp"


def njit(*args, parallel=False, inline="never", **kwargs):
    """``numba.njit`` with the project's cache policy; fastmath is never switched on."""
    opts = dict(cache=_CACHE, parallel=parallel, nogil=True, error_model="numpy", inline=inline)
    opts.update(kwargs)
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


def set_threads(n):
    """Set the number of threads used by parallel kernels (``None``: all cores)."""
    if n is None:
        return numba.config.NUMBA_NUM_THREADS
    n = max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n
