"""The dem stage's periodic cell (docs/periodic.md): the smoke case, its records, resume, config errors."""

import csv
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.engine.periodic_cell import COLUMNS
from demcli.engine.system import System

SMOKE = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "periodic_triaxial.yaml"


def _rows(path):
    """Rows of a record CSV keyed by column name (headers are ``name[unit]``)."""
    with open(path) as f:
        return [{k.split("[")[0]: v for k, v in row.items()} for row in csv.DictReader(f)]


def _records(out, stage):
    found = sorted(Path(out).rglob(f"{stage}_dem.csv"))
    assert found, list(Path(out).rglob("*.csv"))
    return _rows(found[0])


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("periodic") / "run"
    return out, run_case(SMOKE, out=out, quiet=True, threads=1)


def test_smoke_case_compresses_then_shears_the_cell(smoke_run, h5_datasets):
    out, res = smoke_run
    # Given the smoke case (servo compression of a loose cell, then shear along z)
    assert [r.name for r in res] == ["pour", "compress", "shear"]
    comp = _records(out, "compress")
    shear = _records(out, "shear")
    # Then every periodic record has the cell's columns
    assert set(COLUMNS) <= set(comp[0]) and set(COLUMNS) <= set(shear[0])
    # the servo closed the loose cell at -max_rate (no contact carried load) until the spheres
    # touched, then held each normal stress at its target (100 kPa within 1 %)
    assert float(comp[1]["rate_x"]) == -20.0 and float(comp[0]["contacts"]) == 0
    last = comp[-1]
    for a in "xyz":
        assert float(last[f"strain_{a}"]) < -0.15
        assert float(last[f"s_{a}{a}"]) == pytest.approx(1e5, rel=0.01)
    assert float(last["p"]) == pytest.approx(1e5, rel=0.01) and float(last["coordination"]) > 4.0
    assert float(last["porosity"]) < float(comp[0]["porosity"]) - 0.2
    # the shear stage shortened z at its rate (-1 1/s) from the compressed cell
    t = float(shear[-1]["time"]) - float(shear[0]["time"])
    assert float(shear[-1]["strain_z"]) == pytest.approx(np.expm1(-1.0 * t), rel=1e-3)
    assert float(shear[0]["cell_z"]) == pytest.approx(float(comp[-1]["cell_z"]), rel=1e-12)
    # with the cell's figures beside the CSVs
    for stage in ("compress", "shear"):
        for fig in ("stress", "strain"):
            assert (out / "records" / f"{stage}_dem_{fig}.png").stat().st_size > 0
    # and the states keep the cell, every sphere inside it to within half a skin
    st = h5_datasets(res[-1].path)
    lengths = st["cell/lengths"]
    assert np.all(st["bodies/x"] > -0.5 * lengths) and np.all(st["bodies/x"] < 1.5 * lengths)


def test_interrupted_periodic_stage_resumes_bit_identically(smoke_run, tmp_path, monkeypatch, h5_differences):
    from demcli.errors import StageError
    from demcli.kernels import layout as K

    out, res = smoke_run
    real = System.advance

    def interrupted(self, n):  # Ctrl-C in the shear stage (its z axis strain-controlled) at step 200
        if self.cell[K.C_MODE + 2] == K.RATE and self.step >= 200:
            raise KeyboardInterrupt
        return real(self, n)

    # When the same case is interrupted in its shear stage
    monkeypatch.setattr(System, "advance", interrupted)
    with pytest.raises(StageError, match="interrupted"):
        run_case(SMOKE, out=tmp_path / "run", quiet=True, threads=1)
    assert (tmp_path / "run" / "02-shear.ckpt.h5").exists()
    # and resumed
    monkeypatch.setattr(System, "advance", real)
    run_case(SMOKE, out=tmp_path / "run", quiet=True, resume=True, threads=1)
    # Then its final state equals the uninterrupted one bit for bit (cell included)
    for name in ("01-compress.h5", "02-shear.h5"):
        assert h5_differences(out / name, tmp_path / "run" / name) == []


@pytest.mark.parametrize("old, new, needles", [
    ("      gain: 0.01", "      gain: 3", ["stages[1].periodic.gain", "3"]),
    ("      x: {mode: stress, stress: 100 kPa}\n      y", "      x: {mode: stres, stress: 100 kPa}\n      y",
     ["stages[1].periodic.x.mode", "stres"]),
    ("    physics: {friction: true, local_damping: 0.2}\n    periodic:\n      x: {mode: stress, stress: 100 kPa}\n"
     "      y: {mode: stress, stress: 100 kPa}\n      z: {mode: stress",
     "    physics: {friction: true, local_damping: 0.2, gravity: [0, 0, -9.81]}\n    periodic:\n"
     "      x: {mode: stress, stress: 100 kPa}\n      y: {mode: stress, stress: 100 kPa}\n      z: {mode: stress",
     ["stages[1].physics.gravity", "refused with periodic", "no floor"]),
    ("    time: {steps: 1500", "    walls: [{type: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}]\n"
     "    time: {steps: 1500", ["stages[1].walls", "refused with periodic", "no walls"]),
])
def test_bad_periodic_config_exits_2_naming_key_rule_and_value(tmp_path, old, new, needles):
    text = SMOKE.read_text().replace("      max_rate: 20 1/s", "      max_rate: 20 1/s\n      gain: 0.01")
    assert old in text
    case = tmp_path / "case.yaml"
    case.write_text(text.replace(old, new, 1))
    result = CliRunner().invoke(cli, ["check", str(case)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


def test_clumps_in_a_periodic_cell_are_refused_at_the_stage_start(tmp_path):
    # Given the smoke case with clumps drawn (the state alone shows them: demcli check passes)
    text = SMOKE.read_text().replace("count: 300", "count: 50").replace("    material: glass\n  - name: compress",
                                     "    material: glass\n    clump: {spheres: [[-0.5, 0, 0, 0.6], [0.5, 0, 0, 0.6]]}\n"
                                     "  - name: compress", 1)
    case = tmp_path / "case.yaml"
    case.write_text(text)
    assert CliRunner().invoke(cli, ["check", str(case)]).exit_code == 0
    # When it runs, then the periodic stage stops at its start with exit 2, naming the rule
    result = CliRunner().invoke(cli, ["run", str(case), "--out", str(tmp_path / "run"), "--quiet"])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "periodic: is for spheres-only scenes (not clumps or polyhedra yet)" in result.output, result.output
