"""The ``particles`` stage (listed spheres, inline or CSV) and ``add: true`` (particles added to the
scene instead of replacing it): what a validation case needs to set up an impact."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.kernels.layout import FIX_ROTATION, FIX_TRANSLATION
from demcli.state import read_state

ROOT = Path(__file__).resolve().parents[2]

R = 0.01
IMPACT = """\
name: impact
materials:
  glass: {density: 2500 kg/m^3, young: 50 MPa, poisson: 0.3, restitution: 0.5, friction: 0.3}
stages:
  - name: ball
    type: particles
PLACEMENT
  - name: bounce
    type: dem
    physics: {friction: true}
    walls: [{type: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass, rigid: true}]
    time: {duration: 2 ms, dt_factor: 0.02}
    output: {records: 5, snapshots: 0}
"""
INLINE = """\
    particles:
      - {x: [0, 0, 10.001 mm], v: [0.1, 0, -0.2], omega: [0, 0, 0], radius: 10 mm, material: glass}
      - {x: [0.1, 0.1, 0.1], radius: 5 mm, material: glass, fixed: true, v: [0, 0, 0.01]}
"""
CSV = "x,y,z,vx,vy,vz,wx,wy,wz,radius,material,fixed\n0,0,0.010001,0.1,0,-0.2,0,0,0,0.01,glass,0\n" \
      "0.1,0.1,0.1,0,0,0.01,0,0,0,0.005,glass,1\n"


def _case(tmp_path, placement, name="case.yaml"):
    path = tmp_path / name
    path.write_text(IMPACT.replace("PLACEMENT\n", placement))
    return path


def test_listed_spheres_bounce_off_a_rigid_wall_with_their_restitution(tmp_path):
    # Given: a sphere 1 um above a rigid floor at v = (0.1, 0, -0.2) m/s (e = 0.5, mu = 0.3, Hertz),
    # and a fixed sphere far away moving up at 1 cm/s
    path = _case(tmp_path, INLINE)
    # When: the case runs (2 ms: the impact lasts ~0.3 ms)
    run_case(path, out=tmp_path / "run", quiet=True, threads=1)
    first = read_state(tmp_path / "run" / "00-ball.h5")
    last = read_state(tmp_path / "run" / "01-bounce.h5")
    # Then: the stage placed both as listed (mass 4/3 pi r^3 rho, I = 2/5 m r^2, flags of the fixed one)
    b = first.groups["bodies"]
    assert np.allclose(b["x"][0], [0, 0, 0.010001]) and np.allclose(b["v"][0], [0.1, 0, -0.2])
    assert b["mass"][0] == pytest.approx(2500 * 4 / 3 * np.pi * R ** 3, rel=1e-12)
    assert b["inertia"][0, 0] == pytest.approx(0.4 * b["mass"][0] * R ** 2, rel=1e-12)
    assert list(b["flags"]) == [0, FIX_TRANSLATION | FIX_ROTATION]
    # and the ball leaves the floor at e v_n (1 %: restitution exact with tension allowed) with the
    # tangential impulse mu (1 + e) m v_n (tan(theta) = 0.5 < 7/2 mu (1 + e): it may stick at the end,
    # so only the bound v_t' >= v_t - mu (1 + e) v_n is exact)
    v = last.groups["bodies"]["v"]
    assert v[0, 2] == pytest.approx(0.5 * 0.2, rel=0.01)
    assert v[0, 0] >= 0.1 - 0.3 * 1.5 * 0.2 - 1e-9
    # and the fixed sphere kept its velocity and moved with it
    assert np.array_equal(v[1], [0, 0, 0.01])
    assert last.groups["bodies"]["x"][1, 2] == pytest.approx(0.1 + 0.01 * last.meta["time"], rel=1e-12)


def test_a_csv_file_places_the_same_spheres_and_an_edit_runs_the_stage_again(tmp_path):
    # Given: the inline case and the same spheres in a CSV file beside a second case file
    (tmp_path / "balls.csv").write_text(CSV)
    inline, from_file = _case(tmp_path, INLINE, "a.yaml"), _case(tmp_path, "    file: balls.csv\n", "b.yaml")
    # When: both place their spheres
    run_case(inline, out=tmp_path / "a", quiet=True, threads=1, only="ball")
    run_case(from_file, out=tmp_path / "b", quiet=True, threads=1, only="ball")
    # Then: the same bodies and spheres, bit for bit
    a, b = read_state(tmp_path / "a" / "00-ball.h5"), read_state(tmp_path / "b" / "00-ball.h5")
    for group in ("bodies", "spheres"):
        for key, arr in a.groups[group].items():
            assert np.array_equal(arr, b.groups[group][key]), f"{group}/{key}"
    # and an edited file changes the stage's config hash (the stage is not skipped as up to date)
    (tmp_path / "balls.csv").write_text(CSV.replace("0.005", "0.006"))
    run_case(from_file, out=tmp_path / "b", quiet=True, threads=1, only="ball")
    again = read_state(tmp_path / "b" / "00-ball.h5")
    assert again.meta["config_hash"] != b.meta["config_hash"]
    assert again.groups["spheres"]["radius"][1] == pytest.approx(0.006)


@pytest.mark.parametrize("text, needle", [
    ("x,y,z,vx,vy,vz,wx,wy,radius,material\n", "balls.csv:1: header: missing column(s) wz"),
    ("x,y,z,vx,vy,vz,wx,wy,wz,radius,material\n0,0,1,0,0,0,0,0,0,0.01,glass\n0,0,x,0,0,0,0,0,0,0.01,glass\n",
     "balls.csv:3: column z: not a number: 'x'"),
    ("x,y,z,vx,vy,vz,wx,wy,wz,radius,material\n0,0,1,0,0,0,0,0,0,-1,glass\n", "balls.csv:2: column radius"),
    ("x,y,z,vx,vy,vz,wx,wy,wz,radius,material\n0,0,1,0,0,0,0,0,0,0.01,steel\n", "unknown material 'steel'"),
])
def test_a_bad_particle_file_is_one_clear_line_and_exit_code_2(tmp_path, text, needle):
    (tmp_path / "balls.csv").write_text(text)
    path = _case(tmp_path, "    file: balls.csv\n")
    result = CliRunner().invoke(cli, ["run", str(path), "--out", str(tmp_path / "run"), "--quiet", "--only", "ball"])
    assert result.exit_code == 2, result.output
    assert needle in result.output and "Traceback" not in result.output


ADDED = """\
name: added
materials:
  glass: {density: 2500 kg/m^3, young: 50 MPa}
stages:
  - {name: bed, type: generate, region: {shape: box, min: [0, 0, 0], max: [20 mm, 20 mm, 20 mm]}, count: 4,
     radius: {min: 2 mm, max: 2 mm}, material: glass}
  - name: more
    type: generate
    add: true
    region: {shape: box, min: [0, 0, 30 mm], max: [20 mm, 20 mm, 50 mm]}
    count: 3
    radius: {min: 1 mm, max: 1 mm}
    material: glass
  - name: striker
    type: particles
    add: true
    particles: [{x: [10 mm, 10 mm, 60 mm], v: [0, 0, -1], radius: 3 mm, material: glass}]
"""


def test_stages_with_add_extend_the_scene(tmp_path):
    # Given: a bed of 4 spheres, 3 more generated above it (add), then a listed striker (add)
    path = tmp_path / "case.yaml"
    path.write_text(ADDED)
    # When: the case runs
    run_case(path, out=tmp_path / "run", quiet=True, threads=1)
    bed, last = read_state(tmp_path / "run" / "00-bed.h5"), read_state(tmp_path / "run" / "02-striker.h5")
    # Then: 8 bodies, the first 4 the bed's unchanged, ids unique, each sphere on its own body
    b, s = last.groups["bodies"], last.groups["spheres"]
    assert len(b["x"]) == 8 and np.array_equal(b["x"][:4], bed.groups["bodies"]["x"])
    assert sorted(b["id"]) == list(range(8))
    assert np.array_equal(s["body"], np.arange(8))
    assert list(np.round(s["radius"] * 1e3, 6)) == [2.0] * 4 + [1.0] * 3 + [3.0]
    assert np.allclose(b["v"][7], [0, 0, -1])


def test_add_is_refused_where_there_is_no_scene_or_a_polyhedral_one(tmp_path):
    # Given: add on a first stage, and add after a ballast assembly (polyhedra)
    first = ADDED.replace("  - {name: bed, type: generate", "  - {name: bed, type: generate, add: true")
    path = tmp_path / "a.yaml"
    path.write_text(first)
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2 and "first stage" in result.output, result.output
    # and after a stage whose scene holds polyhedra (their bodies stay last)
    deposit = (ROOT / "cases" / "smoke" / "ballast_deposit.yaml").read_text()
    path = tmp_path / "b.yaml"
    path.write_text(deposit + "  - name: extra\n    type: particles\n    add: true\n"
                    "    particles: [{x: [0.1, 0.1, 0.5], radius: 10 mm, material: ballast}]\n")
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2 and "polyhedra" in result.output, result.output


def test_the_state_keeps_each_materials_shear_modulus(tmp_path):
    # Given: one material with the default G and one with its own (#29: materials.<m>.shear)
    path = _case(tmp_path, INLINE)
    path.write_text(path.read_text().replace(
        "friction: 0.3}\n", "friction: 0.3}\n  rubber: {density: 1100 kg/m^3, young: 5 MPa, poisson: 0.49, "
                           "shear: 1 MPa}\n", 1))
    # When: the particles stage runs
    run_case(path, out=tmp_path / "run", quiet=True, threads=1, only="ball")
    # Then: the state's materials group holds E / (2 (1 + nu)) and the given value, exactly
    m = read_state(tmp_path / "run" / "00-ball.h5").groups["materials"]
    assert list(m["name"]) == ["glass", "rubber"]
    assert m["shear"].tolist() == [50e6 / (2 * 1.3), 1e6]
