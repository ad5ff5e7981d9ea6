"""Gradation stage: volumetrics against worked examples, and bad tables rejected clearly."""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"


def test_asphalt_2d_worked_example(tmp_path):
    # Given the seed-001 Marshall section (AC-13, 4.85 % binder, 2640/1100 kg/m3, VV 4 %, r = 50 mm)
    run_case(CASES / "gradation_ac13_2d.yaml", out=tmp_path, quiet=True)
    g = read_state(tmp_path / "00-grading.h5").groups["gradation"]
    # Then, by hand: V_ag = 0.9515/2640, V_as = 0.0485/1100, V_z = (V_ag + V_as)/0.96,
    v_ag = 0.9515 / 2640
    v_z = (v_ag + 0.0485 / 1100) / 0.96
    m = v_ag / v_z * (100 - 26.4) / 100  # share of the section taken by aggregate >= 1.18 mm
    assert m == pytest.approx(0.629546, rel=1e-5)  # 0.855362 x 0.736
    s = math.pi * 0.05 ** 2
    # the class of 4.75-9.5 mm gets (79.7 - 49.8) / (100 - 26.4) of it
    k = list(np.round(g["class_lower"] * 1e3, 2)).index(4.75)
    assert g["class_share"][k] == pytest.approx((79.7 - 49.8) / 73.6 * 100, rel=1e-12)
    assert g["class_amount"][k] == pytest.approx(s * m * (79.7 - 49.8) / 73.6, rel=1e-12)
    # the shares add to 100 %, the empty top classes are zero, eight classes from 1.18 to 31.5 mm
    assert g["class_share"].sum() == pytest.approx(100.0, abs=1e-9)
    assert len(g["class_share"]) == 8 and g["class_share"][-3:].tolist() == [0, 0, 0]
    # and the totals: specimen, aggregate, voids = S VV, mastic the rest
    assert g["totals"].tolist() == pytest.approx([s, s * m, 0.04 * s, s * (1 - m - 0.04)], rel=1e-12)


def test_ballast_worked_example(tmp_path):
    # Given the seed-002 wide gradation in a 0.6 x 0.3 x 0.35 m bed, rho0 1.72, rho1 2.6 g/cm3
    run_case(CASES / "gradation_ballast_wide.yaml", out=tmp_path, quiet=True)
    g = read_state(tmp_path / "00-grading.h5").groups["gradation"]
    # Then n1 = 1 - 1.72/2.6, V_d = (1 - n1) V_c, V_j = P_j V_d with P = 0,0,4,29,46,16,5 %
    vc = 0.6 * 0.3 * 0.35
    vd = 1.72 / 2.6 * vc
    assert g["class_share"].tolist() == pytest.approx([0, 0, 4, 29, 46, 16, 5], abs=1e-12)
    assert g["class_amount"].tolist() == pytest.approx((np.array([0, 0, 4, 29, 46, 16, 5]) / 100 * vd).tolist(),
                                                       rel=1e-12)
    # counts estimated from 40 mm cubes: n_j = P_j V_c / d_m^3
    assert g["class_count"][3] == pytest.approx(0.29 * vc / 0.04 ** 3, rel=1e-12)
    assert g["totals"][2] == pytest.approx((1 - 1.72 / 2.6) * vc, rel=1e-12)
    assert g["class_upper"][-1] == pytest.approx(0.075)


BALLAST = """\
name: g
stages:
  - name: grading
    type: gradation
    sieves:  [16 mm, 25 mm, 35.5 mm, 45 mm, 56 mm, 63 mm]
    passing: [0, 0, 4, 33, 79, 95]
    specimen: {shape: box, size: [0.6 m, 0.3 m, 0.35 m]}
    volumetrics: {kind: ballast, bulk_density: 1.72 g/cm^3, particle_density: 2.6 g/cm^3, max_size: 75 mm}
"""


@pytest.mark.parametrize("old, new, needles", [
    ("passing: [0, 0, 4, 33, 79, 95]", "passing: [0, 0, 40, 33, 79, 95]", ["passing[3]", "must not decrease"]),
    ("passing: [0, 0, 4, 33, 79, 95]", "passing: [0, 0, 4, 33, 79, 105]", ["passing[5]", "must be in [0, 100]"]),
    ("sieves:  [16 mm, 25 mm,", "sieves:  [25 mm, 16 mm,", ["sieves[1]", "ascend"]),
    ("sieves:  [16 mm, 25 mm,", "sieves:  [16 mm, 16 mm,", ["sieves[1]", "empty class"]),
    ("passing: [0, 0, 4, 33, 79, 95]", "passing: [0, 4, 33, 79, 95]", ["passing", "one value per sieve"]),
    ("size: [0.6 m, 0.3 m, 0.35 m]", "size: [0.6 m, 0.05 m, 0.35 m]", ["specimen", "larger than the specimen"]),
    ("max_size: 75 mm}", "max_size: 60 mm}", ["max_size", "must exceed the largest sieve"]),
    ("bulk_density: 1.72 g/cm^3", "bulk_density: 2.72 g/cm^3", ["bulk_density", "below the particle density"]),
])
def test_bad_tables_are_rejected(tmp_path, old, new, needles):
    # Given a valid ballast gradation with one defect
    assert old in BALLAST
    p = tmp_path / "g.yaml"
    p.write_text(BALLAST.replace(old, new, 1))
    # When checked
    result = CliRunner().invoke(cli, ["check", str(p)])
    # Then exit code 2 with the rule and the place
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)
