"""Bad input of every kind: one clear message naming the problem, exit code 2, no traceback."""

import shutil

import pytest
from click.testing import CliRunner

from demcli.cli import cli

GOOD = """\
name: tiny
seed: 1
materials:
  glass: {density: 2500 kg/m^3, young: 50 MPa}
stages:
  - name: pour
    type: generate
    region: {shape: box, min: [0, 0, 0], max: [10 mm, 10 mm, 10 mm]}
    count: 5
    radius: {min: 1 mm, max: 1 mm}
    material: glass
  - name: settle
    type: dem
    physics: {gravity: [0, 0, -9.81], friction: true}
    walls: [{type: box, min: [0, 0, 0], max: [10 mm, 10 mm, 10 mm], material: glass}]
    time: {steps: 10}
"""


def _invoke(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _case(tmp_path, text, name="case.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _assert_clean_error(result, *needles, code=2):
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


@pytest.mark.parametrize("old, new, needles", [
    # misspelt key, with did-you-mean and line
    ("friction: true}", "frictoin: true}", ["case.yaml:14", "stages[1].physics.frictoin", "did you mean 'friction'"]),
    # negative density
    ("density: 2500 kg/m^3", "density: -2500 kg/m^3", ["case.yaml:4", "materials.glass.density", "-2500"]),
    # unit of the wrong dimension
    ("max: 1 mm}", "max: 1 kg}", ["case.yaml:10", "stages[0].radius.max", "not a length"]),
    # unknown stage type
    ("type: dem", "type: dme", ["stages[1].type", "did you mean 'dem'"]),
    # unknown material reference
    ("material: glass\n  - name", "material: glas\n  - name", ["stages[0].material", "unknown material", "glass"]),
    # linear law without its stiffness
    ("time: {steps: 10}", "time: {steps: 10}\n    contact: {law: linear}", ["contact.kn", "needs kn"]),
    # both duration and steps
    ("time: {steps: 10}", "time: {steps: 10, duration: 1 s}", ["stages[1].time", "exactly one"]),
    # duplicate stage names
    ("name: settle", "name: pour", ["stages[1]", "pour"]),
])
def test_malformed_case_gives_one_clear_message(tmp_path, old, new, needles):
    # Given a valid case with one defect
    assert old in GOOD
    path = _case(tmp_path, GOOD.replace(old, new, 1))
    # When it is checked
    result = _invoke(["check", path])
    # Then the defect is named with its location, exit code 2, no traceback
    _assert_clean_error(result, *needles)


def test_every_error_is_reported_at_once(tmp_path):
    # Given a case with three independent defects
    text = GOOD.replace("density: 2500", "density: -1").replace("count: 5", "count: 0").replace("steps: 10", "steps: -3")
    # When checked
    result = _invoke(["check", _case(tmp_path, text)])
    # Then all three are listed
    _assert_clean_error(result, "3 problems", "density", "count", "steps")


def test_not_yaml(tmp_path):
    result = _invoke(["check", _case(tmp_path, "stages: [\n  - {name: a\n")])
    _assert_clean_error(result, "case.yaml:")


def test_missing_case_file(tmp_path):
    result = _invoke(["check", tmp_path / "nope.yaml"])
    _assert_clean_error(result, "nope.yaml")


def test_missing_stage_input(tmp_path):
    # Given a valid case whose first stage never ran
    path = _case(tmp_path, GOOD)
    # When only the second stage is asked for
    result = _invoke(["run", path, "--only", "settle", "--out", tmp_path / "run", "--quiet"])
    # Then the missing input is named
    _assert_clean_error(result, "missing stage input", "00-pour.h5")


def test_unknown_stage_for_from(tmp_path):
    result = _invoke(["run", _case(tmp_path, GOOD), "--from", "setle", "--out", tmp_path / "run"])
    _assert_clean_error(result, "--from setle", "did you mean 'settle'")


def test_bad_override(tmp_path):
    result = _invoke(["check", _case(tmp_path, GOOD), "--set", "seed"])
    _assert_clean_error(result, "seed")


def test_override_violating_a_rule(tmp_path):
    result = _invoke(["check", _case(tmp_path, GOOD), "--set", "stages.pour.count=-4"])
    _assert_clean_error(result, "stages[0].count", "-4")


def test_time_step_above_critical_is_refused(tmp_path):
    # Given an explicit time step far above the critical step
    path = _case(tmp_path, GOOD.replace("time: {steps: 10}", "time: {steps: 10, dt: 1 s}"))
    # When run
    result = _invoke(["run", path, "--out", tmp_path / "run", "--quiet"])
    # Then it is refused before any step, naming the ratio to the critical step
    _assert_clean_error(result, "time.dt", "critical")


def test_info_on_text_file(tmp_path):
    p = tmp_path / "state.h5"
    p.write_text("not hdf5\n")
    _assert_clean_error(_invoke(["info", p]), "state.h5", "not an HDF5")


def test_info_on_truncated_state(tmp_path):
    # Given a real state file cut in half
    run_dir = tmp_path / "run"
    assert _invoke(["run", _case(tmp_path, GOOD), "--out", run_dir, "--quiet"]).exit_code == 0
    src = run_dir / "01-settle.h5"
    cut = tmp_path / "cut.h5"
    data = src.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    # When summarised
    # Then a clear error names the file
    _assert_clean_error(_invoke(["info", cut]), "cut.h5")


def test_foreign_state_as_stage_input(tmp_path):
    # Given a run whose first stage output was replaced by a foreign HDF5 file
    import h5py

    run_dir = tmp_path / "run"
    path = _case(tmp_path, GOOD)
    assert _invoke(["run", path, "--out", run_dir, "--quiet"]).exit_code == 0
    with h5py.File(run_dir / "00-pour.h5", "w") as f:
        f["data"] = [1, 2, 3]
    # When the second stage is re-run from it
    result = _invoke(["run", path, "--only", "settle", "--out", run_dir, "--quiet"])
    # Then the file is named as not a demcli state
    _assert_clean_error(result, "00-pour.h5", "not a demcli state")
