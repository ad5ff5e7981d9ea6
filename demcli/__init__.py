"""demcli: discrete element batch simulator for asphalt mixtures and railway ballast.

Importing the package compiles nothing: numba kernels are imported lazily by the
stages that need them.
"""

__version__ = "0.1.0"


def run_case(case, **options):
    """Run a case file like ``demcli run`` does; see :func:`demcli.pipeline.run_case`."""
    from demcli.pipeline import run_case as _run_case

    return _run_case(case, **options)


__all__ = ["__version__", "run_case"]
