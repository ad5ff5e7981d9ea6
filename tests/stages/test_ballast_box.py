"""The ballast box stages (deposit, vibrate, sleeper; seed 002 sec. 4) on the smoke chain,
their measures against hand computations, and the cost knobs (stiffness and mass scaling).
"""

import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.state import RecordTable, read_state

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "cases" / "smoke" / "ballast_box.yaml"
sys.path.insert(0, str(ROOT / "tests" / "engine"))
TARGET = 2500.0  # the smoke case's plate-removal density [kg/m^3], beyond its bed: drawn, never reached
FIGURES = {}  # the chain's figures: (table, y columns) -> matplotlib Figure


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    out = tmp_path_factory.mktemp("ballast_box")
    figure = RecordTable.figure

    def keep(self, x, ys, **style):
        fig = figure(self, x, ys, **style)
        FIGURES[(self.name, tuple([ys] if isinstance(ys, str) else ys))] = fig
        return fig

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RecordTable, "figure", keep)
        run_case(SMOKE, out=out, quiet=True)
    return out


def _csv(path):
    """Columns of a record CSV by name."""
    return read_record(path)[0]


def _mass_and_density(st):
    vol = st["polyhedron_shapes/volume"][st["polyhedra/shape"]]
    n = len(vol) if "actors/body" not in st else int(st["actors/body"].min())
    return float(vol[:n].sum() * 2600.0)


def test_deposit_comes_to_rest_and_measures_the_bed(chain):
    st = read_state(chain / "03-deposit.h5")
    # Then: the bed group holds rho_b = M / (A h), n = 1 - rho_b / rho_s, e = n / (1 - n) (hand formulas)
    m = _mass_and_density(st)
    h = float(st["bed/height"])
    assert float(st["bed/particle_mass"]) == pytest.approx(m, rel=1e-12)
    assert float(st["bed/bulk_density"]) == pytest.approx(m / (0.24 * 0.15 * h), rel=1e-12)
    n = float(st["bed/porosity"])
    assert n == pytest.approx(1.0 - float(st["bed/bulk_density"]) / 2600.0, rel=1e-12)
    assert float(st["bed/void_ratio"]) == pytest.approx(n / (1.0 - n), rel=1e-12)
    # and the bed is a bed: below the loose stack it fell from (0.30 m), porosity of a loose
    # packing of angular particles in a narrow box (measured 0.59)
    assert 0.3 < n < 0.75 and h < 0.3
    # and the gradation and library travel on for the shoulder fill
    assert "gradation/class_amount" in st and "path" in st.group_attrs["library"]


def test_vibrate_records_density_per_cycle_under_the_plate(chain):
    st = read_state(chain / "04-vibrate.h5")
    csv = chain / "records" / "vibrate_cycles.csv"
    assert csv.exists() and (chain / "records" / "vibrate_cycles_density.png").exists()
    rows = _csv(csv)
    # Then: one row at the start of the cycles and one after each cycle (1 here)
    assert list(rows["cycle"]) == [0, 1]
    # and the density is the particle mass over the box floor times the plate's underside height
    plate = int(st["actors/body"][0])
    assert str(st["actors/name"][0]) in ("plate", "b'plate'")
    m = _mass_and_density(st)
    zb = float(rows["plate"][-1]) - 0.025
    assert rows["bulk_density"][-1] == pytest.approx(m / (0.24 * 0.15 * zb), rel=1e-9)
    assert float(st["bodies/x"][plate, 2]) == pytest.approx(rows["plate"][-1], rel=1e-12)
    # and the plate moved along z only: its x, y are the box centre, its attitude as laid
    assert st["bodies/x"][plate, 0] == pytest.approx(0.12, abs=1e-12)
    assert st["bodies/x"][plate, 1] == pytest.approx(0.075, abs=1e-12)
    # and a load cycle compacts the loose bed (measured 0.86 -> 1.10 g/cm^3)
    assert rows["bulk_density"][-1] > rows["bulk_density"][0]
    # and the plate's response in the cycle (swing, lag of its lowest point behind the peak load)
    # is the fit of its height over the cycle's dem records; none before the cycles start
    _check_response(rows, _csv(chain / "records" / "vibrate_dem.csv"), "plate")


def _check_response(rows, dem_rows, device):
    from demcli.stages.ballast.box import cycle_response

    assert np.isnan(rows["swing"][0]) and np.isnan(rows["lag"][0])
    ref = cycle_response(dem_rows["cycle"], dem_rows[device])
    assert ref["cycle"].tolist() == [1]
    assert rows["swing"][1] == ref["swing"][0] and rows["lag"][1] == ref["lag"][0]
    assert 0.0 < rows["swing"][1] < 0.1 and -0.5 <= rows["lag"][1] < 0.5


def test_cycle_response_of_known_motions():
    from demcli.stages.ballast.box import cycle_response

    # Given a device sampled 4 and 8 times per cycle, moving as m + A cos(2 pi (phase - p_low)) +
    # a drift, lowest at p_low = 0.5 (with the peak load), 0.75 and 0.3, and a cycle with too few samples
    for per_cycle in (4, 8):
        for p_low, lag in ((0.5, 0.0), (0.75, 0.25), (0.3, -0.2)):
            cycle = np.r_[-0.5, 0.0, np.arange(1, 3 * per_cycle + 1) / per_cycle]
            phase = np.clip(cycle, 0.0, None)
            z = 0.4 - 0.01 * np.cos(2 * np.pi * (phase - p_low)) - 1e-6 * phase
            r = cycle_response(cycle, z)
            # Then every whole cycle gives the 20 mm swing and the lag, to the drift's effect
            assert r["cycle"].tolist() == [1, 2, 3]
            np.testing.assert_allclose(r["swing"], 0.02, rtol=1e-3)
            np.testing.assert_allclose(r["lag"], lag, atol=1e-4)
    # and cycles without 3 samples, or not ending on a sample, are left out
    r = cycle_response(np.array([0.0, 0.5, 1.0, 1.5, 1.75]), np.zeros(5))
    assert r["cycle"].tolist() == []


def test_sleeper_fills_the_shoulders_and_records_settlement(chain):
    vib = read_state(chain / "04-vibrate.h5")
    st = read_state(chain / "05-sleeper.h5")
    # Then: the plate is gone, a sleeper is the last body, shoulder ballast was added
    assert [str(n).strip("b'") for n in st["actors/name"]] == ["sleeper"]
    n_before = int(vib["actors/body"][0])
    n_after = int(st["actors/body"][0])
    assert n_after > n_before and len(st["bodies/mass"]) == n_after + 1
    # the shoulder particles rest beside the sleeper, inside the box
    sl = n_after
    new = st["bodies/x"][n_before:n_after]
    assert np.all(np.abs(new[:, 0] - st["bodies/x"][sl, 0]) > 0.03 - 1e-3)
    assert np.all((new[:, :2] > 0) & (new[:, :2] < [0.24, 0.15]))
    # and the settlement record starts at 0 and is the sleeper's descent since the cycles began
    rows = _csv(chain / "records" / "sleeper_settlement.csv")
    assert list(rows["cycle"]) == [0, 1] and rows["settlement"][0] == 0.0
    assert rows["settlement"][-1] == pytest.approx(rows["sleeper"][0] - rows["sleeper"][-1], rel=1e-12)
    assert rows["sleeper"][-1] == pytest.approx(float(st["bodies/x"][sl, 2]), rel=1e-12)
    # the sleeper sinks under the cyclic load (measured 2.5 mm after one cycle)
    assert rows["settlement"][-1] > 0.0
    _check_response(rows, _csv(chain / "records" / "sleeper_dem.csv"), "sleeper")
    assert (chain / "records" / "sleeper_settlement.png").exists()
    assert any((chain / "sleeper").glob("*.pvd"))


def test_cyclic_stages_sample_each_load_cycle_at_least_20_times(chain):
    from demcli.stages.ballast.box import SLEEPER, VIBRATE

    # Given the default of the vibrate and sleeper stages (the smoke case sets none)
    assert VIBRATE["records_per_cycle"].default >= 20 and SLEEPER["records_per_cycle"].default >= 20
    # Then each load cycle of the dem records holds that many rows (before: 4, a zig-zag trace)
    for stage in ("vibrate", "sleeper"):
        cycle = _csv(chain / "records" / f"{stage}_dem.csv")["cycle"]
        assert np.sum((cycle > 1e-9) & (cycle <= 1 + 1e-9)) == VIBRATE["records_per_cycle"].default


def test_ballast_figures_print_the_papers_axes(chain):
    pytest.importorskip("matplotlib")
    # Given the chain's figures: bulk density and void ratio per vibration cycle
    ax = FIGURES[("cycles", ("bulk_density",))].axes[0]
    rows = _csv(chain / "records" / "vibrate_cycles.csv")
    # Then the axes are the paper's words and units, whole cycles, a marker per cycle
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("Vibration cycle", "Bulk density (g/cm³)")
    assert all(float(v).is_integer() for v in ax.get_xticks())
    density, target = ax.get_lines()
    np.testing.assert_allclose(density.get_ydata(), rows["bulk_density"] * 1e-3)
    assert density.get_marker() == "o"
    # and the stage's target density is the dashed line, on the void ratio figure as e = rho_s / rho_t - 1
    assert target.get_label() == "Target 2.5 g/cm³" and np.allclose(target.get_ydata(), 2.5)
    ax = FIGURES[("cycles", ("void_ratio",))].axes[0]
    assert ax.get_ylabel() == "Void ratio" and np.allclose(ax.get_lines()[1].get_ydata(), 2600.0 / TARGET - 1.0)
    # and the settlement in mm per sleeper cycle
    ax = FIGURES[("settlement", ("settlement",))].axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("Sleeper cycle", "Settlement (mm)")
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(),
                               _csv(chain / "records" / "sleeper_settlement.csv")["settlement"] * 1e3)
    # and the sleeper's height through the cycles, every dem record
    ax = FIGURES[("dem", ("sleeper",))].axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("Load cycle", "Sleeper height (mm)")
    assert (chain / "records" / "sleeper_dem_sleeper.png").exists()
    assert (chain / "records" / "vibrate_dem_plate.png").exists()
    # and the kinetic energy on its log axis leaves out the zero it starts from
    ax = FIGURES[("dem", ("kinetic",))].axes[0]
    assert ax.get_yscale() == "log" and np.all(np.asarray(ax.get_lines()[0].get_ydata()) > 0)


def test_cycle_timing_gives_whole_cycles_of_whole_records():
    from demcli.config.schema import Node
    from demcli.stages.ballast.box import cycle_timing

    load = Node({"frequency": 10.0, "settle": 0.013, "min": 0.0, "max": 1.0})
    dt, total, rec = cycle_timing(load, cycles=7, records_per_cycle=4, dt=3.3e-5)
    spc = 4 * rec
    # Then: dt no larger than asked, a cycle is exactly spc steps, the settle rounded up to records
    assert dt <= 3.3e-5 and dt * spc * 10.0 == pytest.approx(1.0, rel=1e-14)
    settle = total - 7 * spc
    assert settle % rec == 0 and settle * dt >= 0.013 and (settle - rec) * dt < 0.013
    # and a settle time of whole records stays that long (0.05 s = 2 records of 0.025 s)
    for dt_asked in (3.975e-06, 1e-5, 3.3e-5):
        load = Node({"frequency": 10.0, "settle": 0.05, "min": 0.0, "max": 1.0})
        dt, total, rec = cycle_timing(load, cycles=3, records_per_cycle=4, dt=dt_asked)
        assert (total - 3 * 4 * rec) == 2 * rec


def test_bed_measures_and_surface_height_of_a_known_layer():
    from demcli.engine.poly_shape import polyhedra_groups
    from demcli.stages.ballast.box import bed_measures, surface_height
    from test_polyhedra_dynamics import box

    # Given: a 3 x 2 layer of 5 cm cubes on the floor of a 15 x 10 cm box
    polys = [box(0.05, 0.05, 0.05) for _ in range(6)]
    x = [[0.025 + 0.05 * i, 0.025 + 0.05 * j, 0.025] for i in range(3) for j in range(2)]
    g = polyhedra_groups(polys, 2600.0, x=x)
    # Then: the surface is at 5 cm and the layer is solid (porosity 0)
    h = surface_height(g, np.zeros(3), np.array([0.15, 0.1, 1.0]), 0.025)
    assert h == pytest.approx(0.05, abs=1e-12)
    m = bed_measures(6 * 0.05 ** 3 * 2600.0, 2600.0, 0.015, h)
    assert m["porosity"] == pytest.approx(0.0, abs=1e-12) and m["bulk_density"] == pytest.approx(2600.0)
    m = bed_measures(1000.0, 2600.0, 1.0, 1.0)
    assert m["porosity"] == pytest.approx(1 - 1000 / 2600) and m["void_ratio"] == pytest.approx(1600 / 1000)


def test_mass_scaling_keeps_weights_and_gives_back_real_masses():
    from demcli.engine.actors import haversine
    from test_actors import _cube_under_plate, _scene

    g = _cube_under_plate(load=haversine(500.0, 500.0, 0.0))
    a = _scene(g)
    b = _scene(g, mass_scale=16.0)
    # Then: the critical step grows by sqrt(16), the stored masses are the real ones, bit for bit
    assert b.critical_dt() == pytest.approx(4.0 * a.critical_dt(), rel=1e-12)
    gb = b.groups()["bodies"]
    np.testing.assert_array_equal(gb["mass"], g["bodies"]["mass"])
    np.testing.assert_array_equal(gb["inertia"], g["bodies"]["inertia"])
    # and the statics are unchanged: the floor carries the real weights plus 500 N (within 0.1 %)
    b.advance(30000)
    f = []
    for _ in range(20):
        b.advance(100)
        f.append(-b.wforce[0, 2])
    assert np.mean(f) == pytest.approx(float(g["bodies"]["mass"].sum()) * 9.81 + 500.0, rel=1e-3)


def test_stiffness_scaling_changes_only_the_moduli():
    # Given: the smoke deposit planned with scaling.stiffness 0.01
    from demcli.stages import dem
    from demcli.stages.base import load_case

    case = load_case(SMOKE, ["stages.3.scaling.stiffness=0.01"])
    cfg = case.stages[3]
    mats = dem.case_materials(case, cfg.scaling.stiffness)
    # Then: every Young's modulus is scaled, nothing else
    for m, (name, ref) in zip(mats, case.materials.items()):
        assert m.young == pytest.approx(ref.young * 0.01, rel=1e-15) and m.density == ref.density


@pytest.mark.parametrize("override, rule", [
    ("stages.4.load.max=-1", "must be"),
    ("stages.3.scaling.mass=3", "power of 2"),
    ("stages.4.scaling.mass=3", "power of 2"),  # the cyclic stages run dem's checks too
    ("stages.5.scaling.mass=6", "power of 2"),
    ("stages.4.walls=[]", "box wall"),
])
def test_bad_ballast_box_input_is_reported(override, rule):
    result = CliRunner().invoke(cli, ["check", str(SMOKE), "--set", override])
    assert result.exit_code == 2, result.output
    assert rule in result.output


def test_shoulder_height_below_the_bed_is_an_input_error(chain, tmp_path):
    import shutil

    # Given: the smoke chain up to the vibrated bed (its surface is ~0.1 m above the floor)
    for f in chain.iterdir():
        if f.name[:2] in ("00", "01", "02", "03", "04"):
            shutil.copy(f, tmp_path / f.name)
    # When: the sleeper stage is asked to fill the shoulders up to 1 cm above the floor
    result = CliRunner().invoke(cli, ["run", str(SMOKE), "--out", str(tmp_path), "--only", "sleeper",
                                      "--set", "stages.5.shoulders.height=0.01"])
    # Then: a clear input error names the key and the bed surface (exit 2), and no state is written
    assert result.exit_code == 2, result.output
    assert "shoulders.height 0.01 m must be above the bed surface" in result.output
    assert not (tmp_path / "05-sleeper.h5").exists()


def test_compare_overlays_the_runs_records(chain, tmp_path):
    import shutil

    # Given: the smoke run and a copy of it under another name
    other = tmp_path / "other_run"
    shutil.copytree(chain / "records", other / "records")
    # When: demcli compare draws the seed's figures
    result = CliRunner().invoke(cli, ["compare", str(chain), str(other), "--out", str(tmp_path / "cmp")])
    assert result.exit_code == 0, result.output
    # Then: one PNG and one CSV per figure column, each CSV holding both runs' curves as recorded
    for stem in ("vibrate_cycles_bulk_density", "vibrate_cycles_void_ratio", "sleeper_settlement_settlement"):
        assert (tmp_path / "cmp" / f"{stem}.png").exists()
    lines = (tmp_path / "cmp" / "sleeper_settlement_settlement.csv").read_text().splitlines()
    src = _csv(chain / "records" / "sleeper_settlement.csv")
    runs = [line.split(",")[0] for line in lines[1:]]
    assert runs == [chain.name] * len(src["cycle"]) + ["other_run"] * len(src["cycle"])
    assert [float(line.split(",")[2]) for line in lines[1:]][:len(src["cycle"])] == src["settlement"].tolist()
    # and a folder without records is a clear input error (exit 2)
    bad = CliRunner().invoke(cli, ["compare", str(tmp_path / "cmp")])
    assert bad.exit_code == 2 and "not a run folder" in bad.output


def test_compare_figures_read_as_the_stages_own(chain):
    pytest.importorskip("matplotlib")
    from demcli.compare import overlay_figure, read_record

    # Given the records of a run, when compare draws the seed figures, then they carry the stages'
    # words and display units, the seed figure's axis words and its 1.55 g/cm^3 line
    data, units = read_record(chain / "records" / "vibrate_cycles.csv")
    ax = overlay_figure("vibrate_cycles", {"a": (data["cycle"], data["bulk_density"])}, "cycle", "bulk_density",
                        units).axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("Vibration cycle", "Bulk density (g/cm³)")
    assert [ln.get_label() for ln in ax.get_lines()] == ["a", "Target 1.55 g/cm³"]
    data, units = read_record(chain / "records" / "sleeper_settlement.csv")
    ax = overlay_figure("sleeper_settlement", {"a": (data["cycle"], data["settlement"])}, "cycle", "settlement",
                        units).axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("Sleeper cycle", "Settlement (mm)")
    assert all(float(v).is_integer() for v in ax.get_xticks())


def test_compare_keeps_the_curves_of_runs_whose_folders_are_gone(chain, tmp_path):
    # Given: an earlier comparison's CSV of the settlement, from this run under two names
    first = tmp_path / "first"
    CliRunner().invoke(cli, ["compare", str(chain), "--record", "sleeper_settlement", "-y", "settlement",
                             "--out", str(first)])
    src = _csv(chain / "records" / "sleeper_settlement.csv")
    old = (first / "sleeper_settlement_settlement.csv").read_text().splitlines()
    earlier = tmp_path / "earlier.csv"
    earlier.write_text("\n".join(old + [line.replace(chain.name, "gone_run", 1) for line in old[1:]]) + "\n")
    # When: the run folder is compared again with that CSV
    result = CliRunner().invoke(cli, ["compare", str(chain), "--with", str(earlier), "--out", str(tmp_path / "cmp")])
    assert result.exit_code == 0, result.output
    # Then: the earlier curves come first, the one sharing the run folder's name labelled with its file
    lines = (tmp_path / "cmp" / "sleeper_settlement_settlement.csv").read_text().splitlines()
    n = len(src["cycle"])
    assert lines[0] == old[0]
    assert [line.split(",")[0] for line in lines[1:]] == (
        [f"{chain.name} (earlier.csv)"] * n + ["gone_run"] * n + [chain.name] * n)
    ys = [float(line.split(",")[2]) for line in lines[1:]]
    assert ys[:n] == ys[n:2 * n] == ys[2 * n:] == src["settlement"].tolist()
    # and a CSV that is not a comparison, or fits none of the figures drawn, is an input error (exit 2)
    bad = tmp_path / "bad.csv"
    bad.write_text("cycle[1],settlement[m]\n1,0.1\n")
    out = CliRunner().invoke(cli, ["compare", str(chain), "--with", str(bad), "--out", str(tmp_path / "x")])
    assert out.exit_code == 2 and "not a demcli compare CSV" in out.output
    density = tmp_path / "cmp" / "vibrate_cycles_bulk_density.csv"
    out = CliRunner().invoke(cli, ["compare", str(chain), "--record", "sleeper_settlement", "--with", str(density),
                                   "--out", str(tmp_path / "x")])
    assert out.exit_code == 2 and "belong to none of the figures drawn (sleeper_settlement)" in out.output


def test_interrupted_sleeper_stage_resumes_bit_identically(chain, tmp_path, h5_differences, interrupt_and_resume):
    import shutil

    from demcli.engine.system import System

    # Given: the smoke chain up to the vibrated bed, and its sleeper stage interrupted (Ctrl-C)
    # during the load cycle (shoulders filled, sleeper and shoulder particles moving); when it
    # is resumed
    for f in chain.iterdir():
        if f.name[:2] in ("00", "01", "02", "03", "04"):
            shutil.copy(f, tmp_path / f.name)
    interrupt_and_resume(System, 12000, SMOKE, tmp_path, "05-sleeper.ckpt.h5")
    # Then: the sleeper state equals the uninterrupted run's, dataset for dataset
    assert h5_differences(chain / "05-sleeper.h5", tmp_path / "05-sleeper.h5") == []


def test_a_linearized_sleeper_stage_resumes_bit_identically(chain, tmp_path, h5_differences, interrupt_and_resume):
    import shutil

    import h5py

    from demcli.engine.system import System
    from demcli.kernels.shapes.polyhedra import BOX_COLS, L_LEFT

    # Given: the smoke chain's vibrated bed and its sleeper stage with the touching pairs' geometry evaluated
    # exactly every 4th step and linearized in between (contact.geometry_refresh, issue #30)
    text = SMOKE.read_text()
    old = "    cycles: 1\n    output: {snapshots: 1}"
    assert text.count(old) == 1
    case = tmp_path / "ballast_box_smoke.yaml"
    case.write_text(text.replace(old, "    cycles: 1\n    contact: {geometry_refresh: 4}\n    output: {snapshots: 1}"))
    straight, resumed = tmp_path / "straight", tmp_path / "resumed"
    for out in (straight, resumed):
        out.mkdir()
        for f in chain.iterdir():
            if f.name[:2] in ("00", "01", "02", "03", "04"):
                shutil.copy(f, out / f.name)
    # When: run straight through, and interrupted in the load cycle then resumed
    run_case(case, out=straight, quiet=True)
    interrupt_and_resume(System, 12000, case, resumed, "05-sleeper.ckpt.h5")
    # Then: both end in the same state, dataset for dataset, which keeps each touching pair's last exact
    # evaluation and its count of linearized steps left (0-3: pairs at every phase of the refresh)
    assert h5_differences(straight / "05-sleeper.h5", resumed / "05-sleeper.h5") == []
    with h5py.File(straight / "05-sleeper.h5") as f:
        kept = f["body_contacts/linearized"][()]
    left = kept[:, L_LEFT - BOX_COLS]  # the stored columns follow the box's
    assert len(kept) > 20 and set(np.unique(left)) == {0.0, 1.0, 2.0, 3.0}
