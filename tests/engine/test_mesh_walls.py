"""Mesh walls (``type: mesh``) run from case files against the analytic plane wall: a flat mesh
gives the plane's forces and trajectories bit for bit (spheres on a face, on an edge and on a
vertex shared by four triangles, a clump bed), a moving flat mesh (velocity, force, servo) pushes
a sphere onto a floor as the moving plane does, a ball rests in the fold of the Marshall head on
two face contacts as the analytic equilibrium says, the mesh is drawn in the snapshots where it is,
a scene without mesh walls has no mesh arrays, bad mesh settings are configuration errors (exit
code 2), and a polyhedral scene takes a mesh wall (not a cylinder)."""

from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.geometry.mesh_file import read_mesh
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"

BALLS = """\
name: flat
materials:
  m: {density: 2500 kg/m^3, young: 10 MPa, poisson: 0.25, friction: 0.4, restitution: 0.5}
stages:
  - name: balls
    type: particles
    particles:
      - {x: [0.01, 0.004, 0.012], v: [0.3, 0.1, -0.2], omega: [5, -20, 3], radius: 5 mm, material: m}
      - {x: [0.03, 0.03, 0.0049], radius: 5 mm, material: m}
      - {x: [0, 0, 0.0049], radius: 5 mm, material: m}
      - {x: [-0.03, 0.01, 0.0049], radius: 5 mm, material: m}
  - name: run
    type: dem
    physics: {gravity: [0, 0, -9.81], friction: true, energy: true}
    walls: [WALL]
    time: {steps: 3000, dt_factor: 0.2}
    output: {records: 30, snapshots: 1, contacts: {}}
"""
PLANE = "{type: plane, name: floor, point: [0, 0, 0], normal: [0, 0, 1], material: m}"
MESH = "{type: mesh, name: floor, file: fan.stl, material: m}"


def fan_stl(folder, half=1.0):
    """A flat square z = 0 of half-width ``half`` [m] as four triangles around its centre vertex
    (the diagonals are edges shared by two triangles, the centre a vertex shared by four)."""
    pts = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0], [0, 0, 0]], float)
    meshio.write(folder / "fan.stl", meshio.Mesh(pts, [("triangle", np.array([[4, 0, 1], [4, 1, 2], [4, 2, 3],
                                                                               [4, 3, 0]]))]), binary=True)


def run(tmp_path, name, text):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    run_case(path, out=tmp_path / name, quiet=True, threads=1)
    return tmp_path / name


def same_run(a, b, stage):
    """The two runs' final bodies and their wall, dem (energies with the strain energy) and contact
    records are bit-identical; returns the first's state and wall record."""
    sa, sb = read_state(a / f"01-{stage}.h5"), read_state(b / f"01-{stage}.h5")
    for key in ("bodies/x", "bodies/v", "bodies/omega", "bodies/force", "walls/force"):
        np.testing.assert_array_equal(sa[key], sb[key], err_msg=key)
    for table in ("walls", "dem", "contacts"):
        if (a / "records" / f"{stage}_{table}.csv").exists():
            ra, _ = read_record(a / "records" / f"{stage}_{table}.csv")
            rb, _ = read_record(b / "records" / f"{stage}_{table}.csv")
            for key in ra:
                np.testing.assert_array_equal(ra[key], rb[key], err_msg=f"{table}: {key}")
    return sa, read_record(a / "records" / f"{stage}_walls.csv")[0]


def test_spheres_on_a_flat_mesh_move_as_on_the_plane(tmp_path):
    # Given four balls on a floor: one dropped sliding and spinning, three pressed 0.1 mm into it at
    # rest, on a shared edge (a diagonal), on the vertex shared by four triangles and on a face;
    # the floor once the plane z = 0, once a flat mesh of four triangles
    fan_stl(tmp_path)
    plane = run(tmp_path, "plane", BALLS.replace("WALL", PLANE))
    mesh = run(tmp_path, "mesh", BALLS.replace("WALL", MESH))
    # Then forces, trajectories, the wall and energy records and the recorded contacts (point,
    # normal, overlap, force) are bit-identical: no feature counted twice
    state, rec = same_run(plane, mesh, "run")
    assert len(read_record(mesh / "records" / "run_contacts.csv")[0]["j"]) > 30
    assert rec["floor.force"].max() > 0.9 * 4 * 2500 * 4 / 3 * np.pi * 0.005 ** 3 * 9.81   # the balls' weight
    assert abs(state["bodies/x"][0, 0] - 0.01) > 0.005                                      # it slid


TOP = {"plane": "{type: plane, name: top, point: [0, 0, 0.0102], normal: [0, 0, -1], material: m, motion: MOTION}",
       "mesh": "{type: mesh, name: top, file: fan.stl, translation: [0, 0, 0.0102], normal: [0, 0, -1], material: m, "
               "motion: MOTION}"}


@pytest.mark.parametrize("motion", ["{mode: velocity, velocity: [0, 0, -0.01]}",
                                    "{mode: force, force: 2 N, mass: 0.01 kg}",
                                    "{mode: servo, stress: 20 kPa, area: 1 cm^2, max_speed: 0.05}"])
def test_moving_mesh_presses_a_sphere_as_the_moving_plane(tmp_path, motion):
    # Given a ball on the floor plane z = 0 under a lid 0.2 mm above it, moved by its motion; the
    # lid once a plane, once a flat mesh (normal -z: servo and force act along it)
    fan_stl(tmp_path, half=0.05)
    text = BALLS.replace("    time: {steps: 3000", "    time: {steps: 2000")
    text = text.replace("\n      - {x: [0.01, 0.004, 0.012], v: [0.3, 0.1, -0.2], omega: [5, -20, 3], radius: 5 mm, "
                        "material: m}", "\n      - {x: [0.001, 0, 0.005], radius: 5 mm, material: m}")
    text = "\n".join(line for line in text.splitlines() if "0.0049" not in line) + "\n"
    runs = [run(tmp_path, kind, text.replace("WALL", PLANE + ", " + TOP[kind].replace("MOTION", motion)))
            for kind in ("plane", "mesh")]
    # Then the lid's position and force, and the ball, are bit-identical
    _, rec = same_run(*runs, "run")
    assert rec["top.force"].max() > 0.1 and rec["top.position"][-1] > rec["top.position"][0]


def test_clumps_on_a_flat_mesh_land_as_on_the_plane(tmp_path):
    # Given the clump smoke case (60 three-sphere clumps poured into a cylinder), its floor once
    # the plane, once a flat mesh square of the cylinder's size
    fan_stl(tmp_path, half=0.015)
    text = (CASES / "smoke" / "clumps.yaml").read_text()
    floor = "{type: mesh, name: floor, file: fan.stl, material: rock}"
    old = text[text.index("{type: plane, name: floor"):text.index("\n", text.index("{type: plane, name: floor"))]
    runs = [run(tmp_path, kind, text.replace(old, new)) for kind, new in (("plane", old), ("mesh", floor))]
    # Then the clumps (members' contacts summed per body) land bit-identically
    state, rec = same_run(*runs, "settle")
    assert np.count_nonzero(rec["floor.force"] > 0.0) > 5      # clumps landed on the floor


CRADLE = """\
name: cradle
materials:
  m: {density: 2500 kg/m^3, young: 10 MPa, poisson: 0.25, friction: 0.0, restitution: 0.5}
stages:
  - name: ball
    type: particles
    particles: [{x: [1 mm, 0, -40 mm], radius: 5 mm, material: m}]
  - name: run
    type: dem
    physics: {gravity: [0, 0, -9.81], local_damping: 0.7}
    contact: {law: linear, kn: 1e4}
    walls: [{type: mesh, name: head, file: HEAD, scale: 0.001, material: m}]
    time: {duration: 1 s, dt_factor: 0.2}
    output: {records: 10, snapshots: 0}
"""


def test_ball_rests_in_the_fold_of_the_marshall_head(tmp_path):
    # Given a frictionless ball (r = 5 mm, linear springs k_n) dropped into the lower Marshall head,
    # an arc of radius R = 50.8 mm in facets of 5 degrees with a fold (a concave edge) at its bottom
    out = run(tmp_path, "cradle", CRADLE.replace("HEAD", str(CASES / "meshes" / "marshall_head.stl")))
    st = read_state(out / "01-run.h5")
    rec, _ = read_record(out / "records" / "run_walls.csv")
    # Then it comes to rest on both facets of the fold: each pushes N = m g / (2 cos 2.5 deg) along its
    # normal, overlap N / k_n, so its centre is at z = -R + (r - N / k_n) / cos 2.5 deg on the fold's plane
    # (R as the binary STL holds it, in float32: 50.8 mm to 1.5e-8; its facet angles off by ~1e-7 rad
    # there, 5e-10 of z)
    radius = -read_mesh(CASES / "meshes" / "marshall_head.stl", scale=0.001)[0][:, 2].min()
    m, c = st["bodies/mass"][0], np.cos(np.radians(2.5))
    n = m * 9.81 / (2 * c)
    assert st["bodies/x"][0, 2] == pytest.approx(-radius + (5e-3 - n / 1e4) / c, rel=2e-9)
    assert abs(st["bodies/x"][0, 0]) < 1e-7 and abs(st["bodies/x"][0, 1]) < 1e-12
    # and the head carries its weight (the sum of the two contacts)
    assert rec["head.force"][-1] == pytest.approx(m * 9.81, rel=1e-12)


def test_mesh_wall_is_drawn_where_it_is(tmp_path):
    # Given the moving lid above: after 2000 steps at 0.01 m/s it is 0.2 mm lower
    fan_stl(tmp_path, half=0.05)
    text = BALLS.replace("WALL", TOP["mesh"].replace("MOTION", "{mode: velocity, velocity: [0, 0, -0.01]}"))
    out = run(tmp_path, "lid", text.replace("steps: 3000", "steps: 200"))
    # When the last walls snapshot is read back with meshio
    back = meshio.read(sorted((out / "run").glob("walls_*.vtu"))[-1])
    # Then it holds the four triangles at the lid's position now, with the wall's data
    tri = back.cells_dict["triangle"]
    z = read_state(out / "01-run.h5")["walls/point"][0, 2]
    rec, _ = read_record(out / "records" / "run_walls.csv")
    assert len(tri) == 4 and np.allclose(back.points[tri][..., 2], z, rtol=0, atol=1e-15)
    assert z < 0.0102 - 1e-6 and z == pytest.approx(-rec["top.position"][-1], rel=1e-12)
    assert np.all(back.cell_data_dict["kind"]["triangle"] == 2)


def test_scenes_without_mesh_walls_carry_no_mesh_arrays(build):
    # Given a sphere on a plane wall: no mesh wall
    from demcli.engine.system import Walls

    s = build.sphere_system([[0, 0, 0.01]], [[0, 0, 0]], 0.01, [build.Material("m", 2500.0)],
                            build.ContactModel(law="linear", kn=1e4, kt=0.0),
                            walls=Walls.fixed_planes([(0, 0, 0)], [(0, 0, 1)]))
    s.advance(10)
    # Then the kernels get no mesh arrays: nothing allocated, the mesh path compiled out
    assert s.kernel_walls().mesh is None and s.wmesh is None


def _check(tmp_path, text, *needles, command="check"):
    path = tmp_path / "case.yaml"
    path.write_text(text)
    out = ["--out", str(tmp_path / "run")] if command == "run" else []
    result = CliRunner().invoke(cli, [command, str(path), *out])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


@pytest.mark.parametrize("wall, needles", [
    ("{type: mesh, file: nothere.stl, material: m}", ["case.yaml", "stages[1].walls[0].file", "file not found"]),
    ("{type: mesh, file: floor.ply, material: m}", ["stages[1].walls[0].file", "must be a .obj or .stl file"]),
    ("{type: mesh, file: fan.stl, scale: 0, material: m}", ["stages[1].walls[0].scale", "must be > 0"]),
    ("{type: mesh, file: fan.stl, normal: [0, 0, 0], material: m}", ["stages[1].walls[0].normal", "zero vector"]),
    ("{type: mesh, file: fan.stl, material: m, motion: {mode: servo, stress: 1 kPa}}",
     ["stages[1].walls[0].motion.area", "a servo mesh needs its loaded area"]),
    ("{type: mesh, file: fan.stl, material: m, motion: {mode: pressure, pressure: 1 kPa, mass: 1 kg}}",
     ["stages[1].walls[0].motion.mode", "mode pressure is for cylinder walls"]),
])
def test_bad_mesh_settings_are_config_errors(tmp_path, wall, needles):
    fan_stl(tmp_path)
    _check(tmp_path, BALLS.replace("WALL", wall), *needles)


def test_unreadable_mesh_stops_the_run_before_any_stage(tmp_path):
    (tmp_path / "fan.stl").write_text("solid broken\n  facet normal 0 0 1\n    outer loop\n")
    _check(tmp_path, BALLS.replace("WALL", MESH), "case.yaml", "stages[1].walls[0].file", "cannot read as STL",
           command="run")
    assert not list(tmp_path.rglob("*.h5"))


def test_mesh_wall_in_a_polyhedral_scene_is_checked_and_a_cylinder_refused(tmp_path):
    # Given the quickstart case (polyhedral ballast) with a mesh wall, then a cylinder, in its deposit stage
    data = yaml.safe_load((CASES / "quickstart.yaml").read_text())
    deposit = next(s for s in data["stages"] if s["type"] == "deposit")
    material = deposit["walls"][0]["material"]
    deposit["walls"].append({"type": "mesh", "file": str(CASES / "meshes" / "marshall_head.stl"), "scale": 0.001,
                             "material": material})
    k = data["stages"].index(deposit)
    path = tmp_path / "mesh.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    # Then demcli check takes the mesh wall (polyhedra touch it through the prisms under its triangles)
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 0, result.output
    # and refuses the cylinder, saying why
    deposit["walls"][-1] = {"type": "cylinder", "base": [0, 0, 0], "radius": 0.1, "height": 0.2, "material": material}
    _check(tmp_path, yaml.safe_dump(data, sort_keys=False), f"stages[{k}].walls[{len(deposit['walls']) - 1}].type",
           "is not for polyhedra", "cylinder walls are for spheres and clumps")