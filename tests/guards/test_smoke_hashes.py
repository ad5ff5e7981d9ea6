"""The refactor guard's own parts (the full run is ``make guard``, not part of ``make test``)."""

import importlib.util
from pathlib import Path

import h5py
import numpy as np

_spec = importlib.util.spec_from_file_location("smoke_hashes", Path(__file__).with_name("smoke_hashes.py"))
guard = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(guard)


def test_hashes_cover_numeric_datasets_and_see_one_flipped_bit(tmp_path):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    x = np.linspace(0.0, 1.0, 7)
    for path, arr in ((a, x), (b, np.r_[x[:-1], np.nextafter(x[-1], 2.0)])):
        with h5py.File(path, "w") as f:
            f["bodies/x"] = arr
            f["bodies/id"] = np.arange(7)
            f["walls/name"] = np.array(["floor"], dtype=object)  # text: not a number, not hashed
    ha, hb = guard.dataset_hashes(a), guard.dataset_hashes(b)
    assert sorted(ha) == ["bodies/id", "bodies/x"]
    assert ha["bodies/id"] == hb["bodies/id"] and ha["bodies/x"] != hb["bodies/x"]


def test_differences_name_each_dataset_that_differs_is_new_or_gone():
    old = {"c.yaml": {"01-s.h5": {"a": "1", "b": "2", "gone": "3"}}}
    new = {"c.yaml": {"01-s.h5": {"a": "1", "b": "X", "new": "4"}}}
    assert guard.differences(old, new) == ["c.yaml 01-s.h5 b: differs", "c.yaml 01-s.h5 gone: gone",
                                           "c.yaml 01-s.h5 new: new"]
    assert guard.differences(old, old) == []
