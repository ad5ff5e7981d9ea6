"""The laboratory tests on the 3D Marshall specimen of the mastic stage (issue #32 items 3 + 5):
``idt``, ``marshall`` and ``dynamic_modulus`` after the seed-000 chain, bonded by the mastic
stage's phase table (``bonds.from_phases``), on the smoke cases
``cases/smoke/marshall_ac13_3d_{idt,marshall,dynamic_modulus}.yaml`` (one chain, one run folder)."""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.kernels.bonds import INTACT
from demcli.stages.asphalt.dynamic_modulus import complex_modulus
from demcli.state import read_state

ROOT = Path(__file__).resolve().parents[2]
SMOKE = {k: ROOT / "cases" / "smoke" / f"marshall_ac13_3d_{k}.yaml" for k in ("idt", "marshall", "dynamic_modulus")}
D, T = 0.020, 0.012  # the smoke chain's cut cylinder


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The three smoke cases into one folder: the chain runs once (same stages, same materials)."""
    out = tmp_path_factory.mktemp("lab3d") / "run"
    for case in SMOKE.values():
        run_case(case, out=out, quiet=True)
    return out


def _sphere_positions(st):
    from scipy.spatial.transform import Rotation

    b = st["spheres/body"]
    q = st["bodies/q"][b]
    return st["bodies/x"][b] + Rotation.from_quat(q[:, [1, 2, 3, 0]]).apply(st["spheres/offset"])


def _no_warning(run, stage):
    log = (run / "log.txt").read_text()
    return not [line for line in log.splitlines() if f"[{stage}] warning" in line]


def _bonds_break_only_under_load(rows, n_bonds):
    """Every phase-table bond is intact at the first row; bonds break only once the load is up."""
    p, intact = np.asarray(rows["load"]), np.asarray(rows["bonds_intact"])
    broken = np.asarray(rows["broken_tension"]) + np.asarray(rows["broken_shear"])
    assert intact[0] == n_bonds and broken[0] == 0
    first = int(np.argmax(broken > 0))
    assert broken[-1] > 0.01 * n_bonds and p[first] > 0.2 * p.max()


def test_idt_on_the_3d_specimen(run):
    rows = read_record(run / "records" / "split_idt.csv")[0]
    res = read_state(run / "06-split.h5")
    p, d = np.asarray(rows["load"]), np.asarray(rows["deformation"])
    k = int(np.argmax(p))
    # Then the load rises to a peak inside the record and falls below half of it (a split specimen)
    assert 0 < k < len(p) - 1 and p[-1] < 0.5 * p[k] and np.all(np.diff(d) > 0)
    # and ITS = 2 P / (pi t D) from the recorded peak, with the cut cylinder's D and t
    assert float(res["idt_result/diameter"]) == pytest.approx(D) and float(res["idt_result/thickness"]) == \
        pytest.approx(T)
    assert float(res["idt_result/peak_load"]) == p[k]
    assert float(res["idt_result/its"]) == pytest.approx(2 * p[k] / (math.pi * T * D), rel=1e-12)
    # and the bonds the phase table made break only under load, mostly in tension (splitting)
    _bonds_break_only_under_load(rows, len(res["bonds/i"]))
    assert rows["broken_tension"][-1] > 3 * rows["broken_shear"][-1]
    # and they broke along the loaded diameter (the plane y = centre, the heads normal to x):
    # their mean distance from it under 0.7 of all bonds' (measured 2.3 mm against 4.7 mm)
    x = _sphere_positions(res)
    mid = 0.5 * (x[res["bonds/i"]] + x[res["bonds/j"]])
    dy = np.abs(mid[:, 1] - x[:, 1].mean())
    assert dy[res["bonds/state"] != INTACT].mean() < 0.7 * dy.mean()
    # and the loading was quasi-static up to the peak (no warning, E_k / W at the peak < 1 %)
    assert float(res["idt_result/kinetic_to_work"]) < 1e-2 and _no_warning(run, "split")
    assert (run / "records" / "split_idt.png").stat().st_size > 0


def test_idt_with_bonded_aggregates(run):
    # Given the idt smoke case with `aggregates: {model: bonded}` (its own mastic and test stage
    # names, so it shares the run folder's chain up to the cut)
    from demcli.stages.asphalt.bonded import member_pairs

    run_case(ROOT / "cases" / "smoke" / "marshall_ac13_3d_idt_bonded.yaml", out=run, quiet=True)
    rows = read_record(run / "records" / "split_bonded_idt.csv")[0]
    res = read_state(run / "06-split_bonded.h5")
    mastic = read_state(run / "05-mastic_bonded.h5")
    # Then every aggregate ball is a body of its own, and every pair of lattice neighbours of one
    # aggregate holds a bond of the INTERNAL model (materials -1), counted apart in the records
    n_agg_balls = int(np.sum(mastic["phases/sphere"] == 0))
    assert len(res["bodies/mass"]) == len(res["spheres/radius"]) > n_agg_balls > 0
    inside = res["bond_models/materials"][res["bonds/model"], 0] < 0
    agg = np.where(mastic["phases/sphere"] == 0, mastic["spheres/body"], -1)
    i, j = member_pairs(_sphere_positions(mastic), agg, 2 * float(mastic["aggregates/ball_radius"]))
    assert inside.sum() == len(i) == rows["intra_intact"][0] > 0
    assert np.array_equal(np.sort(res["bonds/i"][inside] * len(agg) + res["bonds/j"][inside]), np.sort(i * len(agg) + j))
    total = rows["intra_intact"] + rows["intra_broken_tension"] + rows["intra_broken_shear"]
    assert np.all(total == len(i)) and np.all(rows["intra_intact"] <= rows["bonds_intact"])
    broken = res["bonds/state"][inside] != INTACT
    assert rows["intra_broken_tension"][-1] + rows["intra_broken_shear"][-1] == broken.sum()
    # and the bonds VTU marks them
    import meshio

    vtu = meshio.read(sorted((run / "split_bonded").glob("bonds_*.vtu"))[-1])
    assert vtu.cell_data["intra"][0].sum() == len(i)


def test_marshall_on_the_3d_specimen(run):
    rows = read_record(run / "records" / "break_marshall.csv")[0]
    res = read_state(run / "06-break.h5")
    p, d = np.asarray(rows["load"]), np.asarray(rows["deformation"])
    k = int(np.argmax(p))
    # Then the curve rises to a peak and falls; the stability is the peak load, the flow the deformation there
    assert 0 < k < len(p) - 1 and p[-1] < 0.5 * p[k]
    assert float(res["marshall_result/stability"]) == p[k] > 0 and float(res["marshall_result/flow"]) == d[k] > 0
    # and the heads are the ASTM arcs scaled to the cut cylinder's D/2
    assert float(res["marshall_result/head_scale"]) == pytest.approx(0.5 * D / 50.8, rel=1e-6)
    _bonds_break_only_under_load(rows, len(res["bonds/i"]))
    assert float(res["marshall_result/kinetic_to_work"]) < 1e-2 and _no_warning(run, "break")
    assert (run / "records" / "break_marshall.png").stat().st_size > 0


def test_dynamic_modulus_on_the_3d_specimen(run):
    res = read_state(run / "06-dm.h5")
    rows = read_record(run / "records" / "dm_series.csv")[0]
    t, s, e = (np.asarray(rows[c]) for c in ("time", "stress", "strain"))
    f = float(res["dynamic_modulus_result/frequency"][0])
    mod, phase = float(res["dynamic_modulus_result/modulus"][0]), float(res["dynamic_modulus_result/phase_angle"][0])
    # Then |E*| is finite and the strain lags the stress by a Burgers phase angle in (0, 90) deg
    assert np.isfinite(mod) and mod > 0 and 0 < phase < 90
    # and both follow from the measured cycles of the recorded series (after 1 conditioning cycle)
    sel = t >= 1.0 / f - 1e-9
    m2, p2, resid = complex_modulus(t[sel], s[sel], e[sel], f)
    assert m2 == pytest.approx(mod, rel=0.02) and p2 == pytest.approx(phase, abs=0.5) and resid < 0.1
    # and the platen carried the haversine on the cut cylinder's section: stress amplitude sigma_a / 2
    ys = complex_modulus(t[sel], s[sel], np.cos(2 * math.pi * f * t[sel]), f)[0]
    assert ys == pytest.approx(50e3, rel=0.03)
    # and the specimen is compressed along its axis (mean strain positive), quasi-statically
    assert e[sel].mean() > 0
    assert float(res["dynamic_modulus_result/frequency_ratio"][0]) < 0.1
    assert float(res["dynamic_modulus_result/kinetic_to_work"][0]) < 1e-2 and _no_warning(run, "dm")
    # and no Burgers bond broke under 110 kPa
    assert np.all(res["bonds/state"] == INTACT) and len(res["bonds/i"]) > 1000


@pytest.mark.parametrize("case, key, value, words", [
    ("idt", "stages.split.orientation", "axial", ["stages[6].orientation", "indirect tension is diametral"]),
    ("marshall", "stages.break.orientation", "axial", ["stages[6].orientation", "Marshall test is diametral"]),
    ("dynamic_modulus", "stages.dm.orientation", "diametral", ["stages[6].orientation", "test is axial"]),
    ("idt", "stages.cut.shape", "{shape: prism, size: [20 mm, 20 mm, 12 mm]}",
     ["stages[6].orientation", "is a prism; cut a cylinder"]),
])
def test_a_wrong_orientation_is_a_config_error(case, key, value, words):
    # Given a test stage told to load the cylinder the other way (or a prism to load across its axis)
    res = CliRunner().invoke(cli, ["check", str(SMOKE[case]), "--set", f"{key}={value}"])
    # Then demcli check refuses the case, naming the key and the rule (exit code 2)
    assert res.exit_code == 2, res.output
    assert all(w in res.output for w in words) and "Traceback" not in res.output
