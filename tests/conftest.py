"""Shared fixtures: a scratch run folder and the smoke cases."""

import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"


@pytest.fixture(scope="session")
def ballast_library_dir(tmp_path_factory):
    """One ballast library folder for the whole test session (content-addressed, so cases that
    ask for the same library share one file safely)."""
    return tmp_path_factory.getbasetemp() / "ballast_library"


@pytest.fixture
def smoke_case():
    return CASES / "smoke" / "beads.yaml"


def _h5_datasets(path):
    import h5py

    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


def _h5_differences(a, b):
    """Names of the datasets that differ between HDF5 files a and b (NaN equals NaN), and of
    those only one of them holds."""
    import numpy as np

    da, db = _h5_datasets(a), _h5_datasets(b)
    out = sorted(set(da) ^ set(db))
    for k in sorted(set(da) & set(db)):
        u, v = np.asarray(da[k]), np.asarray(db[k])
        if not np.array_equal(u, v, equal_nan=u.dtype.kind == "f"):
            out.append(k)
    return out


@pytest.fixture
def h5_differences():
    """``h5_differences(a, b)``: the datasets of two state files that are not bit-identical."""
    return _h5_differences


@pytest.fixture
def h5_datasets():
    """``h5_datasets(path)``: every dataset of a state file as {name: array}."""
    return _h5_datasets


@pytest.fixture
def interrupt_and_resume(monkeypatch):
    """``interrupt_and_resume(system_class, step, case, out, checkpoint)``: run ``case`` into
    ``out`` with Ctrl-C raised once a ``system_class`` reaches ``step``, check that the
    interrupted stage left ``checkpoint`` (a file name in ``out``), then resume it."""
    from demcli import run_case
    from demcli.errors import StageError

    def run(system_class, step, case, out, checkpoint):
        real = system_class.advance

        def interrupted(self, n):
            if self.step >= step:
                raise KeyboardInterrupt
            return real(self, n)

        monkeypatch.setattr(system_class, "advance", interrupted)
        with pytest.raises(StageError, match="interrupted"):
            run_case(case, out=out, quiet=True)
        assert (Path(out) / checkpoint).exists()
        monkeypatch.setattr(system_class, "advance", real)
        run_case(case, out=out, quiet=True, resume=True)

    return run


def _wait_for_files(proc, paths, timeout=300.0):
    """Wait until every path exists while ``proc`` (a subprocess.Popen) still runs; the
    default timeout leaves room for a cold numba cache to compile first."""
    deadline = time.monotonic() + timeout
    while not all(Path(p).exists() for p in paths):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.1)


@pytest.fixture
def wait_for_files():
    """:func:`_wait_for_files`: e.g. checkpoint files that show a child's runs are stepping."""
    return _wait_for_files
