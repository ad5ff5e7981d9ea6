"""Record tables: rows, CSV with units, storage in the state, plots."""

import importlib

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


# ---------------------------------------------------------------------------------------
# figures as a paper prints them: words and display units, ticks, markers, targets, log axes
# ---------------------------------------------------------------------------------------

def _cycles(n=6):
    """A per-cycle table of the vibrate stage: bulk density [kg/m^3] per whole cycle."""
    importlib.import_module("demcli.stages.ballast.box")  # declares the columns

    t = RecordTable("cycles", {"cycle": "1", "bulk_density": "kg/m^3", "void_ratio": "1"})
    for k in range(n):
        t.append(cycle=k, bulk_density=1400.0 + 10.0 * k, void_ratio=0.8 - 0.01 * k)
    return t


def test_axes_carry_words_and_the_papers_units(table):
    pytest.importorskip("matplotlib")
    # Given the per-cycle densities, stored in kg/m^3 (as the CSV keeps them)
    t = _cycles()
    # When they are drawn
    ax = t.figure("cycle", "bulk_density").axes[0]
    # Then the axes read "Load cycle" and "Bulk density (g/cm³)", the values in g/cm^3
    assert ax.get_xlabel() == "Load cycle" and ax.get_ylabel() == "Bulk density (g/cm³)"
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), t.to_arrays()["bulk_density"] * 1e-3)
    # and the CSV still holds the stored unit
    assert t.to_csv_text().splitlines()[0] == "cycle[1],bulk_density[kg/m^3],void_ratio[1]"
    # and an undeclared column is its name in words, in its stored unit ("1": no unit)
    ax = table.figure("step", ["time"]).axes[0]
    assert ax.get_xlabel() == "Step" and ax.get_ylabel() == "Time (s)"


def test_cycles_get_integer_ticks_and_per_cycle_points_markers():
    pytest.importorskip("matplotlib")
    from matplotlib.ticker import MaxNLocator

    from demcli.state.plots import MARKER_POINTS

    # Given per-cycle records (few points) and a long time series
    ax = _cycles(4).figure("cycle", "void_ratio").axes[0]
    # Then the cycle axis ticks whole cycles only, and each record is a marker
    assert isinstance(ax.xaxis.get_major_locator(), MaxNLocator)
    assert all(float(v).is_integer() for v in ax.get_xticks())
    assert ax.get_lines()[0].get_marker() == "o"
    long = RecordTable("dem", {"time": "s", "kinetic": "J"})
    for k in range(MARKER_POINTS + 1):
        long.append(time=0.01 * k, kinetic=1.0 + k)
    assert long.figure("time", "kinetic").axes[0].get_lines()[0].get_marker() in (None, "None", "")
    # and 80 sleeper cycles are still 81 measurements, one marker each
    ax = _cycles(81).figure("cycle", "bulk_density").axes[0]
    assert ax.get_lines()[0].get_marker() == "o"


def test_target_is_a_dashed_line_in_the_legend():
    pytest.importorskip("matplotlib")
    # Given the seed's plate-removal density, 1.55 g/cm^3 = 1550 kg/m^3 (the stored unit)
    ax = _cycles().figure("cycle", "bulk_density", targets={"bulk_density": 1550.0}).axes[0]
    # Then a horizontal line at 1.55 in the plotted unit, named in the legend
    target = [ln for ln in ax.get_lines() if ln.get_label().startswith("Target")]
    assert [ln.get_label() for ln in target] == ["Target 1.55 g/cm³"]
    np.testing.assert_allclose(target[0].get_ydata(), 1.55)
    assert target[0].get_linestyle() == "--" and ax.get_legend() is not None


def test_log_axis_leaves_out_what_it_cannot_show(table):
    pytest.importorskip("matplotlib")
    # Given a kinetic energy of 0 at t = 0 (the bodies start at rest)
    t = RecordTable("dem", {"time": "s", "kinetic": "J"})
    for k, ke in enumerate([0.0, 0.5, 0.2, -0.0, 0.1]):
        t.append(time=0.1 * k, kinetic=ke)
    # When drawn on a logarithmic axis
    line = t.figure("time", "kinetic", logy=True).axes[0].get_lines()[0]
    # Then only the positive values are drawn (no drop to the axis edge)
    assert np.all(np.asarray(line.get_ydata()) > 0) and list(line.get_xdata()) == [0.1, 0.2, 0.4]


def test_gradation_curve_ticks_the_sieve_sizes():
    pytest.importorskip("matplotlib")
    importlib.import_module("demcli.stages.specimen.gradation")  # declares sieve and passing

    # Given the seed-002 sieve curve in mm
    sieves = [16, 25, 35.5, 45, 56, 63]
    curve = RecordTable("curve", {"sieve": "mm", "passing": "%"})
    for s, q in zip(sieves, [0, 0, 4, 33, 79, 95]):
        curve.append(sieve=s, passing=q)
    # When drawn on a logarithmic sieve axis
    ax = curve.figure("sieve", "passing", logx=True).axes[0]
    # Then each sieve size is a tick, labelled as printed, with no decade ticks between
    assert ax.get_xscale() == "log" and list(ax.get_xticks()) == sieves
    assert [lb.get_text() for lb in ax.get_xticklabels()] == ["16", "25", "35.5", "45", "56", "63"]
    assert len(ax.xaxis.get_minorticklocs()) == 0
    assert ax.get_xlabel() == "Sieve size (mm)" and ax.get_ylabel() == "Passing (%)"
    assert all(lb.get_rotation() == 0 for lb in ax.get_xticklabels())
    # and the close sieves of AC-13 (13.2, 16, 19 mm) turn their labels upright rather than overlap
    ac13 = RecordTable("curve", {"sieve": "mm", "passing": "%"})
    for s, q in zip([1.18, 2.36, 4.75, 9.5, 13.2, 16, 19, 26.5, 31.5], [26.4, 37.6, 49.8, 79.7, 95, 100, 100, 100, 100]):
        ac13.append(sieve=s, passing=q)
    ax = ac13.figure("sieve", "passing", logx=True).axes[0]
    assert len(ax.get_xticks()) == 9 and all(lb.get_rotation() == 90 for lb in ax.get_xticklabels())


def test_several_columns_share_the_words_they_have_in_common():
    pytest.importorskip("matplotlib")
    # Given the energy terms of the dem table and the walls' forces
    e = RecordTable("dem", {"time": "s", "kinetic": "J", "strain": "J", "friction": "J"})
    e.append(time=0.0, kinetic=1.0, strain=2.0, friction=0.5)
    w = RecordTable("walls", {"time": "s", "box.x0.force": "N", "box.z1.force": "N"})
    w.append(time=0.0, **{"box.x0.force": 1.0, "box.z1.force": 2.0})
    # Then the axis is the shared quantity and the legend tells the lines apart
    ax = e.figure("time", ["kinetic", "strain", "friction"]).axes[0]
    assert ax.get_ylabel() == "Energy (J)"
    assert [ln.get_label() for ln in ax.get_lines()] == ["Kinetic", "Strain", "Lost to friction"]
    ax = w.figure("time", ["box.x0.force", "box.z1.force"]).axes[0]
    assert ax.get_ylabel() == "Wall force (N)" and [ln.get_label() for ln in ax.get_lines()] == ["box.x0", "box.z1"]
    assert ax.get_legend() is not None


def test_a_declaration_applies_to_its_unit_and_table_only(monkeypatch):
    importlib.import_module("demcli.stages.ballast.box")  # declares the columns
    from demcli.state import records
    from demcli.state.records import column_spec, describe_column

    monkeypatch.setattr(records, "_COLUMNS", dict(records._COLUMNS))  # the probe stays out of the docs
    # Given bulk_density declared in kg/m^3, and a column declared for one table only
    describe_column("probe_col", "Probe in table t", "m", "mm", 1e3, table="t")
    # Then a column of that name in another unit is not rescaled
    assert column_spec("bulk_density", "g/cm^3").scale == 1.0
    assert column_spec("bulk_density", "kg/m^3").axis_label() == "Bulk density (g/cm³)"
    # and the table's declaration is for that table
    assert column_spec("probe_col", "m", "t").label == "Probe in table t"
    assert column_spec("probe_col", "m", "other").label == "Probe col"
    # and the walls' pattern names the wall
    assert column_spec("lid.position", "m", "walls").axis_label() == "Wall lid position (mm)"
    with pytest.raises(ValueError, match="ticks"):
        describe_column("probe_col", "x", ticks="log")


def test_display_factors_agree_with_the_unit_library():
    from demcli.state.fields import register_all
    from demcli.state.records import declared_columns
    from demcli.units import to_si

    register_all()
    # Given every declaration that converts for display (percent and cycles are not pint units)
    checked = 0
    for table, name, c in declared_columns():
        if c.display is None or c.display in ("%", "cycle"):
            continue
        # Then its factor is 1 / (one display unit in the stored unit)
        assert c.scale * to_si(f"1 {c.display}", c.unit) == pytest.approx(1.0), (table, name)
        checked += 1
    assert checked >= 5


def test_units_are_printed_as_a_paper_prints_them():
    from demcli.state.plots import axis_label, pretty_unit

    assert pretty_unit("g/cm^3") == "g/cm³" and pretty_unit("mm^2") == "mm²" and pretty_unit("1/s") == "1/s"
    assert pretty_unit("N*s/m") == "N·s/m" and pretty_unit("m^-1") == "m⁻¹"
    assert pretty_unit("1") == "" and axis_label("void ratio", "1") == "Void ratio"
    assert axis_label("Settlement", "mm") == "Settlement (mm)"


def test_docs_list_every_declared_column():
    from pathlib import Path

    from demcli.state.fields import register_all
    from demcli.state.records import DOC_BEGIN, DOC_END, columns_markdown

    # Given every module's declarations, when docs/records.md is read, then its generated table is
    # the current one (regenerate with demcli.state.records.write_columns_doc())
    register_all()
    text = (Path(__file__).resolve().parents[2] / "docs" / "records.md").read_text(encoding="utf-8")
    assert text.split(DOC_BEGIN, 1)[1].split(DOC_END, 1)[0].strip() == columns_markdown().strip(), \
        "docs/records.md is out of date: run demcli.state.records.write_columns_doc()"
