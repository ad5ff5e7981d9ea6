"""demcli: discrete element batch simulator for asphalt mixtures and railway ballast.

Importing the package compiles nothing: numba kernels are imported lazily by the
stages that need them.
"""

import os as _os

# The kernels are numba's (OpenMP threads, demcli.jit); numpy's and scipy's OpenBLAS pools only
# do small set-up algebra here, and their threads spin after each call on the cores the
# kernels use. One BLAS thread unless the user asks otherwise (before numpy loads OpenBLAS).
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"


def run_case(case, **options):
    """Run a case file like ``demcli run`` does; see :func:`demcli.pipeline.run_case`."""
    from demcli.pipeline import run_case as _run_case

    return _run_case(case, **options)


__all__ = ["__version__", "run_case"]
