"""Record tables: rows, CSV with units, storage in the state, plots."""

import numpy as np
import pytest

from demcli.state import RecordTable, read_state, write_state
from demcli.state.fields import example_state


@pytest.fixture
def table():
    t = RecordTable("energy", {"time": "s", "kinetic": "J", "step": ""})
    for k in range(3):
        t.append({"time": 0.1 * k, "kinetic": 1.0 / (k + 1), "step": 10 * k})
    return t


def test_csv_has_units_and_full_precision(tmp_path, table):
    # When the table is written as CSV
    text = table.write_csv(tmp_path / "records" / "energy.csv").read_text()
    lines = text.splitlines()
    # Then the header carries units, ints stay ints, floats round-trip exactly
    assert lines[0] == "time[s],kinetic[J],step"
    assert lines[3].split(",")[2] == "20"
    assert float(lines[2].split(",")[1]) == 0.5 and float(lines[3].split(",")[0]) == 0.1 * 2


def test_arrays_dtypes(table):
    arrays = table.to_arrays()
    assert arrays["step"].dtype == np.int64 and arrays["time"].dtype == np.float64
    assert len(table) == 3


def test_bad_rows_are_rejected(table):
    # Given a row with a typo'd column / a missing column / a text value
    with pytest.raises(ValueError, match=r"unknown \['kinetc'\]"):
        table.append({"time": 1.0, "kinetc": 2.0, "step": 1})
    with pytest.raises(ValueError, match=r"missing \['step'\]"):
        table.append({"time": 1.0, "kinetic": 2.0})
    with pytest.raises(ValueError, match="needs a number"):
        table.append({"time": 1.0, "kinetic": "2", "step": 1})
    # Then nothing was appended
    assert len(table) == 3


def test_stored_in_state_and_back(tmp_path, table):
    # Given a state carrying the table
    state = example_state()
    table.to_state(state)
    # When the state is written, read, and the table rebuilt
    back = RecordTable.from_state(read_state(write_state(tmp_path / "s.h5", state)), "energy")
    # Then columns, units and values survive, and appending continues
    assert back.columns == table.columns
    assert back.to_csv_text() == table.to_csv_text()
    back.append(time=0.3, kinetic=0.2, step=30)
    assert len(back) == 4


def test_plot_png(tmp_path, table):
    pytest.importorskip("matplotlib")
    # When two columns are plotted against time
    path = tmp_path / "energy.png"
    assert table.plot(path, "time", ["kinetic", "step"]) is True
    # Then a PNG is written
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_without_matplotlib(tmp_path, table, monkeypatch):
    # Given matplotlib is not importable
    import builtins

    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name.startswith("matplotlib"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    # When plotting / Then False and no file
    assert table.plot(tmp_path / "e.png", "time", "kinetic") is False
    assert not (tmp_path / "e.png").exists()
