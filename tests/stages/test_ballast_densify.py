"""The vibrate stage's densification aid (``densify``, issue #31 item 2): a bed below its target
density vibrates on at a lower friction between its particles until it is within the tolerance."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.stages.ballast.box import aid_levels
from demcli.state import read_state

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "cases" / "smoke" / "ballast_box.yaml"
TARGET = 1250.0  # kg/m^3: the smoke bed reaches ~1.10 g/cm^3 in 2 cycles at its friction 0.67
MU0, MU_AID, RAMP, AFTER, CYCLES, TOL = 0.67, 0.1, 4, 2, 12, 0.002


def _case(tmp_path):
    """The smoke box up to its vibrate stage, with a target above its reach and the aid."""
    case = yaml.safe_load(SMOKE.read_text())
    case["stages"] = case["stages"][:5]
    vib = case["stages"][4]
    vib.update({"cycles": CYCLES, "target_density": f"{TARGET / 1e3} g/cm^3",
                "densify": {"after": AFTER, "friction": MU_AID, "ramp": RAMP, "tolerance": TOL}})
    path = tmp_path / "densify.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def densified(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("densify")
    case = _case(tmp)
    run_case(case, out=tmp / "run", quiet=True)
    return case, tmp / "run"


def test_aid_levels_follow_the_rule():
    # Given cycle-end densities, a target of 100 and the aid from cycle 2 in 4 steps
    rho = [0, 50, 60, 62, 64, 70, 90, 95, 96]
    # Then: cycle 1 unaided; cycle 2 starts it (level 1); cycles 3, 4: gap 38, 36 > 3 x gain 2 -> up;
    # cycle 5: gap 30 > 3 x 6 -> up to 4; cycle 6: gap 10 < gain 20 -> down; cycle 7: gap 5 = gain 5 ->
    # kept; cycle 8: gap 4 > 3 x 1 -> up
    assert aid_levels(rho, after=2, ramp=4, target=100) == [0, 0, 1, 2, 3, 4, 3, 3, 4]
    # and at or above the target the level is kept (the stage stops there)
    assert aid_levels([0, 50, 100, 101], after=1, ramp=4, target=100) == [0, 1, 1, 1]


def test_a_stalled_bed_is_densified_to_its_target(densified):
    _, out = densified
    rows = read_record(out / "records" / "vibrate_cycles.csv")[0]
    rho, mu = np.asarray(rows["bulk_density"]), np.asarray(rows["bed_friction"])
    # Then: at the case's friction the bed was below the target after `after` cycles (the aid had work)
    assert np.all(mu[:AFTER + 1] == MU0) and rho[AFTER] < 0.95 * TARGET
    # and the stage stopped at the first cycle end within the tolerance, before its last cycle
    n = len(rho) - 1
    assert n < CYCLES and rho[-1] >= TARGET * (1 - TOL) and np.all(rho[:-1] < TARGET * (1 - TOL))
    # and the friction of each cycle is the level the rule gives from the densities before it
    levels = aid_levels(list(rho), AFTER, RAMP, TARGET)
    for k in range(1, n + 1):
        assert mu[k] == pytest.approx(MU0 + (MU_AID - MU0) * levels[k - 1] / RAMP, rel=1e-12)
    assert mu.min() < MU0
    # and the state's bed is the last row's
    st = read_state(out / "04-vibrate.h5")
    assert float(st["bed/bulk_density"]) == pytest.approx(rho[-1], rel=1e-12)


def test_an_aided_stage_resumes_bit_identically(densified, tmp_path, h5_differences, interrupt_and_resume):
    import shutil

    from demcli.engine.system import System

    case, out = densified
    for f in out.iterdir():
        if f.name[:2] in ("00", "01", "02", "03"):
            shutil.copy(f, tmp_path / f.name)
    # Given the vibrate stage interrupted in its third cycle (the first aided one), then resumed
    interrupt_and_resume(System, 60000, case, tmp_path, "04-vibrate.ckpt.h5")
    # Then the state equals the uninterrupted run's, dataset for dataset
    assert h5_differences(out / "04-vibrate.h5", tmp_path / "04-vibrate.h5") == []


@pytest.mark.parametrize("override, rule", [
    ("stages.4.densify={after: 1, friction: 0.1}", "give target_density too"),
    ("stages.4.densify={after: 5, friction: 0.1}", "must be below cycles"),
])
def test_bad_densify_input_is_reported(override, rule):
    args = ["check", str(SMOKE), "--set", override, "--set", "stages.4.cycles=5"]
    if "target" in rule:
        args += ["--set", "stages.4.target_density=null"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2, result.output
    assert rule in result.output and "densify" in result.output
