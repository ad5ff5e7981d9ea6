"""The memory a stage's particles will take, against what this machine has, checked at validation.

A stage that makes many particles (``generate`` with ``count: 100000000``) would otherwise
pass ``demcli check`` and fail minutes into ``demcli run`` on an allocation. The estimate is
generous (:data:`BYTES_PER_SPHERE`), so a case refused here could not have run.
"""

import os

from demcli.config.schema import NOVALUE
from demcli.errors import InputError

BYTES_PER_SPHERE = 3072
"""Bytes per sphere of a scene the engine integrates, rounded up: the sphere's arrays and its
body's (position, velocity, orientation, spin, force, torque, mass, inertia, ids: ~0.4 kB),
neighbour-list pairs with their force and friction history (up to ~12 per sphere, ~0.13 kB
each: ~1.6 kB), and the copies kept for the last good state and the snapshots (~0.6 kB)."""

BYTES_PER_POLYHEDRON = 8192
"""Bytes per polyhedron of a ballast library, rounded up: up to ~60 vertices and their faces'
CSR tables (~3 kB), its shape indices, and the hull and sieve work arrays while it is built."""


def _cgroup_limit():
    """The memory limit of this process's cgroup (v2), or None."""
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as f:
            text = f.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def declared_memory():
    """``$DEMCLI_MEMORY`` in bytes (``256 GiB``, ``64GB``, ``2e11``): the memory of the machine
    that will run the case, for a check made elsewhere (a cluster's login node); None unset."""
    text = os.environ.get("DEMCLI_MEMORY", "").strip()
    if not text:
        return None
    units = {"kib": 2 ** 10, "mib": 2 ** 20, "gib": 2 ** 30, "tib": 2 ** 40, "kb": 1e3, "mb": 1e6, "gb": 1e9,
             "tb": 1e12, "b": 1, "": 1}
    number = text.rstrip("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ ")
    unit = text[len(number):].strip().lower()
    try:
        value = float(number) * units[unit]
    except (ValueError, KeyError):
        raise InputError(f"DEMCLI_MEMORY={text!r}: give bytes or a number with KiB, MiB, GiB, TiB, kB, MB, GB or TB, "
                         "e.g. DEMCLI_MEMORY='256 GiB'") from None
    return value if value > 0 else None


def machine_memory():
    """Bytes of memory this process can use: ``$DEMCLI_MEMORY`` when set (:func:`declared_memory`),
    else the machine's physical memory, or less where an address-space limit or a cgroup says
    so; None where unknown."""
    declared = declared_memory()
    if declared is not None:
        return declared
    limits = [_cgroup_limit()]
    try:
        limits.append(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        pass
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        limits.append(None if soft == resource.RLIM_INFINITY else soft)
    except (ImportError, ValueError, OSError):
        pass
    limits = [v for v in limits if v is not None and v > 0]
    return min(limits) if limits else None


def _gib(n_bytes):
    return f"{n_bytes / 2 ** 30:.3g} GiB"


def check_memory(report, key, count, what, value=NOVALUE, kind="spheres", bytes_each=BYTES_PER_SPHERE):
    """Report at ``key`` when ``count`` particles (``what``: where they come from; ``kind``:
    spheres or polyhedra, ``bytes_each`` apiece) need more memory than this machine has,
    naming the estimate and the machine's figure."""
    available = machine_memory()
    need = float(count) * bytes_each
    if available is None or need <= available:
        return
    report(key, f"{what}: about {float(count):.3g} {kind} need an estimated {_gib(need)} of memory "
                f"({bytes_each} bytes each), more than this machine's {_gib(available)}", value,
           "make the scene smaller (fewer or larger particles), or, checking for a bigger machine, "
           "set DEMCLI_MEMORY to its memory (e.g. DEMCLI_MEMORY='256 GiB')")
