"""Polyhedral particles as rigid clumps of spheres (``clumpify``): exact mass properties, the
ball count and volume error against the ball size, and a clump bed that the sphere engine runs
with a plate laid on it and loaded like the polyhedral ``vibrate`` plate."""

from pathlib import Path

import numpy as np
import pytest

from demcli import run_case
from demcli.engine.poly_shape import polyhedra_groups
from demcli.geometry import convex_hull
from demcli.stages.ballast.clumps import clump_groups
from demcli.state import State, read_state
from demcli.state.polyhedra import rotation_matrices
from demcli.state.order import sphere_rows_by_id

CASES = Path(__file__).resolve().parents[2] / "cases"
RHO = 2600.0


def cuboid(a, b, c):
    return convex_hull(np.array([[i * a / 2, j * b / 2, k * c / 2] for i in (-1, 1) for j in (-1, 1)
                                 for k in (-1, 1)]))


def stone(seed=3):
    """A ballast-like convex polyhedron: the hull of 40 points on a 60 x 40 x 30 mm ellipsoid."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(40, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return convex_hull(u * [0.03, 0.02, 0.015])


def test_clumps_keep_the_exact_mass_centre_and_inertia_of_a_cuboid():
    # Given a 42 x 32 x 22 mm cuboid body, turned, moving and spinning
    a, b, c = 0.042, 0.032, 0.022
    q = np.array([[0.9, 0.3, -0.2, 0.25]])
    groups = polyhedra_groups([cuboid(a, b, c)], RHO, x=[[0.1, 0.2, 0.3]], q=q, v=[[0.1, 0, -0.2]],
                              omega=[[1.0, -2.0, 0.5]])
    # When it becomes a clump of 5 mm balls
    bodies, spheres, clumps, n = clump_groups(groups, np.array([0.005]))
    # Then the body is the cuboid's, bit for bit, with the analytic mass and principal moments
    for key in ("x", "v", "q", "omega", "mass", "inertia"):
        assert np.array_equal(bodies[key], groups["bodies"][key]), key
    m = RHO * a * b * c
    assert bodies["mass"][0] == pytest.approx(m, rel=1e-12)
    moments = sorted([m * (b * b + c * c) / 12, m * (a * a + c * c) / 12, m * (a * a + b * b) / 12])
    assert bodies["inertia"][0] == pytest.approx(moments, rel=1e-12)
    # and the sphere engine takes it as a clump of those mass properties (same kinetic energy)
    from demcli.engine.materials import ContactModel, Material
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System, Walls

    sys_ = System({"bodies": bodies, "spheres": spheres}, [Material("ballast", RHO)], ContactModel(),
                  make_plan([], clumps=True), Walls(), Dynamics(gravity=(0, 0, 0)), dt=1e-5)
    rot = rotation_matrices(bodies["q"])[0]
    w_body = rot.T @ bodies["omega"][0]
    ke = 0.5 * m * float(bodies["v"][0] @ bodies["v"][0]) + 0.5 * float(w_body @ (bodies["inertia"][0] * w_body))
    assert sys_.kinetic_energy() == pytest.approx(ke, rel=1e-12)
    # and the members are the 9 x 7 x 5 lattice balls of 5 mm whose centres are inside (a ball
    # at the centroid, the outer ones 1 mm inside a face), with the voxel volume error recorded
    assert clumps["balls"][0] == 9 * 7 * 5 and n == 1
    assert np.allclose(spheres["radius"], 0.0025)
    assert clumps["volume_error"][0] == pytest.approx(315 * 0.005 ** 3 / (a * b * c) - 1, rel=1e-12)
    box = np.sort([a, b, c])[::-1] / 2  # principal frame: ascending moments = longest axis first
    assert np.all(np.abs(spheres["offset"]) <= box + 1e-12)


def test_ball_count_and_volume_error_follow_the_ball_size():
    # Given a ballast-like polyhedron (V ~ 50 cm^3)
    poly = stone()
    groups = polyhedra_groups([poly], RHO)
    counts, errors = [], []
    for s in (0.012, 0.008, 0.005, 0.003, 0.002):
        # When it is carved from balls of s
        _, spheres, clumps, _ = clump_groups(groups, np.array([s]))
        counts.append(int(clumps["balls"][0]))
        errors.append(abs(float(clumps["volume_error"][0])))
        # Then every ball centre is inside the polyhedron (body frame)
        v = spheres["offset"]
        sh = groups["polyhedron_shapes"]
        assert np.all(v @ sh["face_normal"].T <= sh["face_offset"] + 1e-9 * s)
    # and the count grows as V / s^3 while the voxel volume error shrinks (O(s / size))
    assert counts == sorted(counts) and counts[0] >= 1
    assert counts[-1] == pytest.approx(poly.volume / 0.002 ** 3, rel=0.05)
    assert errors[-1] < 0.03 and errors[-1] < errors[0]
    # and whole-ball membership keeps the balls inside the faces, so fewer of them
    _, spheres, clumps, _ = clump_groups(groups, np.array([0.005]), membership="whole")
    sh = groups["polyhedron_shapes"]
    assert np.all(spheres["offset"] @ sh["face_normal"].T + 0.0025 <= sh["face_offset"] + 1e-9)
    assert 0 < clumps["balls"][0] < counts[2]


@pytest.fixture(scope="module")
def smoke(tmp_path_factory, ballast_library_dir):
    out = tmp_path_factory.mktemp("ballast_clumps")
    run_case(CASES / "smoke" / "ballast_clumps.yaml", out=out, quiet=True,
             overrides=[f"stages.library.directory={ballast_library_dir}"])
    return out


def test_clump_bed_runs_in_the_sphere_engine(smoke):
    # Given the smoke chain: assembly -> clumpify -> dem deposit -> dem plate
    poly = read_state(smoke / "02-assembly.h5")
    clumps = read_state(smoke / "03-clumps.h5")
    dep = read_state(smoke / "04-deposit.h5")
    # Then every polyhedron became one clump with its own mass and inertia
    assert np.array_equal(clumps["bodies/mass"], poly["bodies/mass"])
    assert np.array_equal(clumps["bodies/inertia"], poly["bodies/inertia"])
    assert np.array_equal(np.unique(clumps["spheres/body"]), np.arange(len(poly["bodies/mass"])))
    assert "polyhedra" not in clumps.groups and clumps["clumps/balls"].sum() == len(clumps["spheres/radius"])
    # and the sphere engine ran it as clumps: the bodies fell, stayed rigid, kept their masses
    assert "clumps" in list(dep.meta["effects"])
    assert dep["bodies/x"][:, 2].mean() < clumps["bodies/x"][:, 2].mean()
    assert np.array_equal(dep["spheres/offset"][sphere_rows_by_id(dep)],  # bodies followed by id: the
                          clumps["spheres/offset"][sphere_rows_by_id(clumps)])  # deposit reorders them
    # and a per-class record of ball counts and volume errors was written
    rec = (smoke / "records" / "clumps_classes.csv").read_text().splitlines()
    assert rec[0].startswith("lower[mm],upper[mm],particles[1],ball_diameter[mm],balls_mean[1]")
    assert (smoke / "clumps" / "spheres.pvd").exists()


def test_plate_is_laid_on_the_bed_and_loaded_like_the_vibrate_plate(smoke):
    # Given the plate stage: a force-controlled plane wall laid 2 mm above the deposited clumps
    dep = read_state(smoke / "04-deposit.h5")
    top = float((State(groups=dep.groups).sphere_centres()[:, 2] + dep["spheres/radius"]).max())
    rows = (smoke / "records" / "plate_walls.csv").read_text().splitlines()
    head = rows[0].split(",")
    z0 = -float(rows[1].split(",")[head.index("plate.position[m]")])  # position = point . normal, normal -z
    # Then it starts 2 mm above the highest ball
    assert z0 == pytest.approx(top + 0.002, abs=1e-12)
    # and it carries F_min + its weight, held until the start, then the haversine (the wall's
    # prescribed mean force is F_mean + M g)
    st = read_state(smoke / "05-plate.h5")
    k = list(st["walls/name"]).index("plate")
    assert st["walls/target"][k] == pytest.approx(3250.0 + 10.5 * 9.81, rel=1e-12)
