"""Indirect tension (``idt``, issue #32): the stage's records and ITS, the elastic stress at the
centre of the disk against the Brazilian solution, and the rate check."""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.state import read_state

SMOKE = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "indirect_tension.yaml"
CENTRE = "stages.split.measure=[{name: centre, type: cylinder, base: [0, 0, 0], axis: [0, 0, 1], radius: 5 mm, " \
         "span: [0, 4 mm]}]"
D, T = 20e-3, 4e-3


@pytest.fixture(scope="module")
def split(tmp_path_factory):
    out = tmp_path_factory.mktemp("idt") / "run"
    run_case(SMOKE, out=out, overrides=[CENTRE], quiet=True)
    return out


def test_the_disk_splits_and_its_strength_is_2p_over_pi_t_d(split):
    rows = read_record(split / "records" / "split_idt.csv")[0]
    p, d = np.asarray(rows["load"]), np.asarray(rows["deformation"])
    broken = np.asarray(rows["broken_tension"]) + np.asarray(rows["broken_shear"])
    res = read_state(split / "01-split.h5")
    # Then the result is the record's peak and ITS = 2 P_max / (pi t D) of the prepared cylinder
    k = int(np.argmax(p))
    assert float(res["idt_result/peak_load"]) == p[k] and float(res["idt_result/deformation_at_peak"]) == d[k]
    assert float(res["idt_result/its"]) == pytest.approx(2 * p[k] / (math.pi * T * D), rel=1e-12)
    assert float(res["idt_result/diameter"]) == D and float(res["idt_result/thickness"]) == T
    assert np.allclose(rows["tensile_stress"], 2 * p / (math.pi * T * D), rtol=1e-12)
    # and the specimen failed: bonds broke around the peak, the load fell to half of it, and the stage
    # stopped there, before its largest deformation (3 % of D)
    assert broken[k] > 0 and broken[-1] > broken[k] and p[-1] < 0.5 * p[k] and d[-1] < 0.03 * D
    # and the loading was quasi-static (kinetic energy at the peak far below the work done)
    assert float(res["idt_result/kinetic_to_work"]) < 1e-2


def test_the_centre_stress_follows_the_brazilian_solution(split):
    # Given the centre region's stress while the disk is elastic (from the first load to the first break)
    m = read_record(split / "records" / "split_measure_centre.csv")[0]
    rows = read_record(split / "records" / "split_idt.csv")[0]
    p = np.asarray(rows["load"])
    broken = np.asarray(rows["broken_tension"]) + np.asarray(rows["broken_shear"])
    first, last = int(np.argmax(p > 0)) + 1, int(np.argmax(broken > 0)) - 1
    assert last - first >= 5
    # Then the horizontal stress across the loaded diameter changes as the elastic disk's,
    # d sigma_yy / dP = -2 / (pi t D) (tension; the measure counts compression positive), within 5 %
    # (the released specimen's residual stress shifts it, so the slope is compared)
    slope = np.polyfit(p[first:last + 1], np.asarray(m["sigma_yy"])[first:last + 1], 1)[0]
    assert slope == pytest.approx(-2 / (math.pi * T * D), rel=0.05)


def test_halving_the_speed_leaves_the_strength(split, tmp_path):
    import shutil

    shutil.copy(split / "00-prepare.h5", tmp_path / "00-prepare.h5")
    run_case(SMOKE, out=tmp_path, overrides=["stages.split.speed=5 mm/s"], quiet=True)
    its = [float(read_state(f / "01-split.h5")["idt_result/its"]) for f in (split, tmp_path)]
    assert its[1] == pytest.approx(its[0], rel=0.01)


def test_bad_idt_input_is_reported():
    result = CliRunner().invoke(cli, ["check", str(SMOKE), "--set", "stages.split.speed=-1"])
    assert result.exit_code == 2 and "speed" in result.output and "Traceback" not in result.output
