"""The one numba wrapper every kernel uses.

Cache policy: on unless ``DEMCLI_NUMBA_CACHE=0``, in a folder named after a digest of
every demcli source that holds compiled code (under ``$NUMBA_CACHE_DIR``, default
``~/.cache/demcli/numba``). Numba checks only the time stamp of a kernel's own file, so
a kernel that inlines a helper from another file (the step loop and the contact and
bond laws) would otherwise keep running the old helper after an edit; with the digest,
any edit compiles afresh. Threading layer: OpenMP, set explicitly before any parallel
kernel compiles (numba's default picks TBB where it is installed, which scales poorly
for these loops). ``NUMBA_DISABLE_JIT=1`` runs the kernels as Python for coverage.
"""

import gc
import hashlib
import math
import os
from pathlib import Path

import numba
from numba.core import event

_CACHE = os.environ.get("DEMCLI_NUMBA_CACHE", "1") != "0"

if os.environ.get("NUMBA_THREADING_LAYER") is None:
    numba.config.THREADING_LAYER = "omp"

COMPILE_GC_THRESHOLD = (200_000, 50, 1_000)
"""Python's garbage-collector thresholds while numba compiles. Numba's front end allocates
millions of short-lived objects (IR nodes, deep copies of inlined functions' IR, typing
templates); at Python's default (700, 10, 10) a full collection runs every ~70 000 net
allocations and scans every live object, the compiler's own growing heap included. With
these thresholds a cold compile of the polyhedral smoke case holds the compiler 12 % less
(50.1 -> 44.2 s, 2 alternated pairs, bench/README.md)."""


class _CompileGC(event.Listener):
    """Raises the collector's thresholds from the start of the outermost numba compile to its
    end (nested compiles of callees included), then restores the caller's."""

    def __init__(self):
        self.depth = 0
        self.saved = gc.get_threshold()

    def on_start(self, ev):
        if self.depth == 0:
            self.saved = gc.get_threshold()
            gc.set_threshold(*COMPILE_GC_THRESHOLD)
        self.depth += 1

    def on_end(self, ev):
        self.depth -= 1
        if self.depth == 0:
            gc.set_threshold(*self.saved)


event.register("numba:compile", _CompileGC())


def kernel_digest():
    """sha256 (16 hex digits) of the demcli sources that define compiled code, and of every kernels
    module (layout.py holds the flags, counters and tuples the kernels are compiled against)."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        text = path.read_bytes()
        if b"njit" in text or path.parent.name == "kernels":  # layout.py: flags, counters, tuples
            h.update(path.relative_to(root).as_posix().encode() + b"\0" + text)
    return h.hexdigest()[:16]


def cache_dir():
    """Where compiled kernels of these sources are cached."""
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "demcli", "numba")
    return os.path.join(base, kernel_digest())


if _CACHE:
    numba.config.CACHE_DIR = cache_dir()


INTERNAL = dict(no_cpython_wrapper=True, no_cfunc_wrapper=True)
"""Options of a kernel called only by other kernels: numba builds no Python (or C) entry wrapper for
it. The wrapper unboxes every argument from Python objects; for a kernel that takes tuples of
arrays or tens of arrays it is a large share of its compile time (~0.3 s for Bodies + Contacts).
Calling such a kernel from Python crashes the interpreter, so only kernels whose every caller is
a kernel are marked (``internal=True``)."""


def njit(*args, parallel=False, inline="never", internal=False, **kwargs):
    """``numba.njit`` with the project's cache policy; fastmath is never switched on. ``internal``:
    called only from other kernels (:data:`INTERNAL`)."""
    opts = dict(cache=_CACHE, parallel=parallel, nogil=True, error_model="numpy", inline=inline)
    if internal:
        opts.update(INTERNAL)
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
