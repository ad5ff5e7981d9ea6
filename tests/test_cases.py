"""Every shipped case (studies included) validates; every smoke case runs end to end with its invariants."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.state import read_state
from demcli.state.order import sphere_rows_by_id

CASES = Path(__file__).resolve().parent.parent / "cases"

FULL = sorted(CASES.glob("*.yaml"))
SMOKE = sorted((CASES / "smoke").glob("*.yaml"))
STUDIES = sorted((CASES / "studies").glob("*.yaml"))


@pytest.mark.parametrize("case", FULL + SMOKE + STUDIES, ids=lambda p: p.name)
def test_case_validates_and_plans(case):
    result = CliRunner().invoke(cli, ["check", str(case)])
    assert result.exit_code == 0, result.output
    assert "valid" in result.output
    if "type: dem" in case.read_text():
        assert "time step:" in result.output and "critical" in result.output


def test_planar_mode_keeps_motion_in_plane(tmp_path):
    # Given the 2D smoke case (disks, gravity along -y, a servo lid)
    run_case(CASES / "smoke" / "planar.yaml", out=tmp_path, quiet=True)
    st = read_state(tmp_path / "01-settle.h5")
    # Then nothing left the plane: z, v_z and the in-plane spin components are exactly zero
    assert np.all(st["bodies/x"][:, 2] == 0.0) and np.all(st["bodies/v"][:, 2] == 0.0)
    assert np.all(st["bodies/omega"][:, :2] == 0.0)
    # and disks carry masses per unit thickness (rho t pi r^2) and I = m r^2 / 2
    r = st["spheres/radius"]
    assert np.allclose(st["bodies/mass"], 2650 * 1e-3 * np.pi * r ** 2, rtol=1e-12)
    assert np.allclose(st["bodies/inertia"][:, 2], 0.5 * st["bodies/mass"] * r ** 2, rtol=1e-12)
    assert st.meta["dim"] == 2 and "planar" in list(st.meta["effects"])


def test_clumps_stay_rigid_and_inside_the_mould(tmp_path):
    # Given the clump smoke case (three-sphere clumps in a cylinder)
    run_case(CASES / "smoke" / "clumps.yaml", out=tmp_path, quiet=True)
    before = read_state(tmp_path / "00-pour.h5")
    after = read_state(tmp_path / "01-settle.h5")
    # Then each body still has its three members at the same mutual distances
    # (the settle stage stores its fresh scene in cell order: bodies are followed by id)
    def member_gaps(st):
        c = st.sphere_centres()[sphere_rows_by_id(st)].reshape(-1, 3, 3)
        return np.linalg.norm(c[:, :, None] - c[:, None, :], axis=-1)
    assert np.allclose(member_gaps(before), member_gaps(after), atol=1e-12)
    # and orientations are unit quaternions, spheres inside the mould (15 mm) up to the overlap guard
    assert np.allclose(np.linalg.norm(after["bodies/q"], axis=1), 1.0, atol=1e-12)
    c = after.sphere_centres()
    assert np.all(np.hypot(c[:, 0], c[:, 1]) + after["spheres/radius"] < 15e-3 * 1.05)
    assert np.all(c[:, 2] - after["spheres/radius"] > -0.5e-3)
    # and the bodies fell: the mean height dropped
    assert after["bodies/x"][:, 2].mean() < before["bodies/x"][:, 2].mean() - 2e-3


def test_check_compiles_no_kernel():
    # Given a fresh interpreter that checks the quickstart case
    import subprocess
    import sys

    code = (
        "import sys, numba\n"
        "from demcli.check import describe_case\n"
        "describe_case(sys.argv[1])\n"
        "import demcli.kernels.engine as a, demcli.kernels.neighbors as b, demcli.kernels.motion as c\n"
        "d = [f for m in (a, b, c) for f in vars(m).values() if isinstance(f, numba.core.dispatcher.Dispatcher)]\n"
        "assert d, 'no kernels found'\n"
        "print(sum(len(f.signatures) for f in d))\n")
    out = subprocess.run([sys.executable, "-c", code, str(CASES / "quickstart.yaml")], capture_output=True,
                         text=True, check=True)
    # Then no kernel has a compiled signature
    assert out.stdout.strip() == "0"


def test_mesh_heads_press_the_bed(tmp_path):
    # Given the mesh-wall smoke case: spheres settled in the lower Marshall head (a mesh), the upper
    # head (the same mesh turned over) coming down at 0.1 m/s for 0.08 s
    from demcli.compare import read_record

    run_case(CASES / "smoke" / "mesh_head.yaml", out=tmp_path, quiet=True, threads=1)
    rec, _ = read_record(tmp_path / "records" / "press_walls.csv")
    st = read_state(tmp_path / "02-press.h5")
    # Then the upper head moved v t (its position along its normal -z grows), met the bed and
    # carries a load that the lower head and the end plates take up, the bed's weight besides
    assert rec["upper.position"][-1] - rec["upper.position"][0] == pytest.approx(0.1 * rec["time"][-1], rel=1e-9)
    assert rec["upper.force"][0] == 0.0 and rec["upper.force"][-1] > 10.0
    weight = float(st["bodies/mass"].sum()) * 9.81
    assert rec["lower.force"][1] == pytest.approx(weight, rel=0.5)
    held = rec["lower.force"][-1] + rec["front.force"][-1] + rec["back.force"][-1]
    assert held > rec["upper.force"][-1]
    # and the spheres stay in the cradle: above the arc of radius 50.8 mm (up to the overlap guard)
    c, r = st.sphere_centres(), st["spheres/radius"]
    assert np.all(np.hypot(c[:, 0], c[:, 2]) + r < 50.8e-3 * 1.01) and np.all(np.abs(c[:, 1]) < 38.1e-3)
    # and the snapshots draw both heads: 2 x 128 triangles
    import meshio

    assert len(meshio.read(sorted((tmp_path / "press").glob("walls_*.vtu"))[-1]).cells_dict["triangle"]) == 256
