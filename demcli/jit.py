"""The one numba wrapper every kernel uses.

Cache policy: on unless ``DEMCLI_NUMBA_CACHE=0``. Threading layer: OpenMP, set
explicitly before any parallel kernel compiles (numba's default picks TBB where it
is installed, which scales poorly for these loops). ``NUMBA_DISABLE_JIT=1`` runs the
kernels as Python for coverage.
"""

import math
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


def free_cores():
    """Cores not busy with other work, from the 1-minute load average (at least 1).

    OpenMP threads spin at every barrier; a thread whose core is taken by another process
    stalls all the others, so asking for more threads than free cores can be 10 times
    slower than one thread. Results do not depend on the thread count.
    """
    cores = numba.config.NUMBA_NUM_THREADS
    try:
        load = os.getloadavg()[0]
    except OSError:
        return cores
    return max(1, min(cores, int(math.floor(cores - load + 0.5))))


def set_threads(n):
    """Set the number of threads used by parallel kernels (``None``: the free cores)."""
    n = free_cores() if n is None else int(n)
    n = max(1, min(n, numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n
