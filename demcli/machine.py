"""The machine a run computes on, as far as it decides the run's round-off.

Same case and seed give bit-identical states on one kind of machine; another CPU model (another
instruction set for numba's code, other BLAS kernels under numpy and scipy) or other library
versions round differently, and a packing amplifies that into another realisation. Every state
file names its machine in ``meta/machine`` (provenance: not part of ``state_hash``, so a stage
resumed on another machine still takes its checkpoint).
"""

from __future__ import annotations

import functools
import platform
from pathlib import Path


def _cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo ('' where there is none)."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == "model name":
            return value.strip()
    return ""


@functools.lru_cache(maxsize=None)
def machine() -> str:
    """One line: CPU model, the CPU numba compiles for, OS, and the numerical libraries' versions."""
    import llvmlite.binding as llvm
    import numba
    import numpy
    import scipy

    cpu = _cpu_model() or platform.processor() or platform.machine()
    return (f"{cpu} (numba target {llvm.get_host_cpu_name()}); {platform.system()} {platform.machine()}; "
            f"Python {platform.python_version()}, numpy {numpy.__version__}, scipy {scipy.__version__}, "
            f"numba {numba.__version__}")
