"""The ballast box chain on a bed of sphere clumps (cases/smoke/ballast_box_clumps.yaml): the
polyhedral plate and sleeper load the clumps in one mixed scene (#28: shapes mixed from a case
file), the bed measures of a clump bed against hand computations, and the refusals.
"""

import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.state import State, read_state

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "cases" / "smoke" / "ballast_box_clumps.yaml"
sys.path.insert(0, str(ROOT / "tests" / "engine"))
FLOOR = 0.24 * 0.15  # the box floor [m^2]
PLATE = 0.05  # the plate's default thickness [m]


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    out = tmp_path_factory.mktemp("ballast_box_clumps")
    run_case(SMOKE, out=out, quiet=True)
    return out


def _bed_bodies(st):
    """Indices of the clumps (the bodies before the first actor)."""
    n = len(st["bodies/mass"])
    return np.arange(int(st["actors/body"].min()) if "actors/body" in st and len(st["actors/body"]) else n)


def test_the_clump_bed_is_deposited_and_measured_by_hand_formulas(chain):
    st = read_state(chain / "04-deposit.h5")
    # Then: a sphere scene of clumps (no polyhedra) whose bed mass is the clumps' (each its polyhedron's V rho)
    assert len(st["spheres/radius"]) > len(st["bodies/mass"]) and len(st.get("polyhedra/shape", ())) == 0
    m = float(st["bodies/mass"].sum())
    assert float(st["bed/particle_mass"]) == pytest.approx(m, rel=1e-12)
    # the surface: mean over columns of the highest sphere top, above the floor; rho_b = M / (A h)
    top = st.sphere_centres()[:, 2] + st["spheres/radius"]
    h = float(st["bed/height"])
    assert 0.0 < h <= top.max() + 1e-12
    assert float(st["bed/bulk_density"]) == pytest.approx(m / (FLOOR * h), rel=1e-12)
    assert float(st["bed/porosity"]) == pytest.approx(1.0 - float(st["bed/bulk_density"]) / 2600.0, rel=1e-12)


def test_the_plate_loads_the_clumps_in_one_mixed_scene(chain):
    st = read_state(chain / "05-vibrate.h5")
    nb = len(st["bodies/mass"])
    # Then: the clumps first, the plate last and its one polyhedron row; the spheres all belong to clumps
    assert len(st["polyhedra/shape"]) == 1 and st["actors/body"].tolist() == [nb - 1]
    assert st["spheres/body"].max() < nb - 1
    dep = read_state(chain / "04-deposit.h5")
    assert nb == len(dep["bodies/mass"]) + 1
    # the plate carried the load into the bed: it ends below where it was laid and the clumps moved
    x_plate = float(st["bodies/x"][-1, 2])
    rows = read_record(chain / "records" / "vibrate_dem.csv")[0]
    assert x_plate == pytest.approx(float(rows["plate"][-1]), rel=1e-12) and x_plate < float(rows["plate"][0])
    assert np.abs(st["bodies/x"][:-1] - dep["bodies/x"]).max() > 1e-3
    # the bed under the plate: h = the plate's underside (hand formula)
    h = x_plate - 0.5 * PLATE
    assert float(st["bed/height"]) == pytest.approx(h, rel=1e-12)
    assert float(st["bed/bulk_density"]) == pytest.approx(float(dep["bed/particle_mass"]) / (FLOOR * h), rel=1e-12)


def test_the_sleeper_replaces_the_plate_and_records_settlement(chain):
    st = read_state(chain / "06-sleeper.h5")
    vib = read_state(chain / "05-vibrate.h5")
    nb = len(st["bodies/mass"])
    # Then: the same clumps, the plate gone, the sleeper the one polyhedron (no shoulders)
    assert nb == len(vib["bodies/mass"]) and len(st["polyhedra/shape"]) == 1
    assert st["actors/body"].tolist() == [nb - 1]
    set_on = float(vib["bodies/x"][-1, 2]) - 0.5 * PLATE  # the plate's underside at the end of vibrate
    rows = read_record(chain / "records" / "sleeper_settlement.csv")[0]
    assert list(rows["cycle"]) == [0, 1]
    assert rows["settlement"].tolist() == pytest.approx([0.0, float(rows["sleeper"][0] - rows["sleeper"][-1])],
                                                        rel=1e-12)
    assert rows["sleeper"][-1] == pytest.approx(float(st["bodies/x"][-1, 2]), rel=1e-12)
    # laid 2 mm above the plate's underside (centre 3 cm higher), it settled onto the bed: it sank
    assert float(rows["sleeper"][0]) < set_on + 0.002 + 0.03 and float(rows["settlement"][-1]) > 0.0


def test_mixed_snapshots_hold_the_clumps_and_the_actor(chain):
    st = read_state(chain / "05-vibrate.h5")
    last = sorted((chain / "vibrate").glob("polyhedra_*.vtu"))[-1]
    # Then: one polyhedra and one spheres series, numbered alike, and walls
    spheres = sorted((chain / "vibrate").glob("spheres_*.vtu"))
    assert [p.name[-10:] for p in spheres] == [p.name[-10:] for p in sorted((chain / "vibrate").glob("polyhedra_*"))
                                               if p.suffix == ".vtu"]
    assert (chain / "vibrate" / "walls.pvd").exists()
    # the polyhedra file draws the plate (body nb - 1) where the state has it, the spheres file every ball
    poly = meshio.read(last)
    nb = len(st["bodies/mass"])
    assert set(poly.cell_data["body"][0].tolist()) == {nb - 1}
    z = poly.points[:, 2]
    assert z.min() == pytest.approx(st["bodies/x"][-1, 2] - 0.5 * PLATE, abs=1e-9)
    assert z.max() == pytest.approx(st["bodies/x"][-1, 2] + 0.5 * PLATE, abs=1e-9)
    balls = meshio.read(spheres[-1])
    np.testing.assert_allclose(balls.points, st.sphere_centres(), atol=1e-12)


def test_top_points_of_a_sphere_bed_are_the_sphere_tops():
    from demcli.engine.actors import add_actor, box_polyhedron
    from demcli.stages.ballast.box import _top, _top_in, top_points
    from test_mixed_scene import sphere_groups

    # Given: two spheres (r 1 cm) at z = 2 and 5 cm, and a plate actor above them
    g = sphere_groups([[0.02, 0.02, 0.02], [0.08, 0.02, 0.05]], r=0.01)
    g = add_actor(g, box_polyhedron([0.1, 0.1, 0.02]), [0.05, 0.05, 0.3], 7800.0, 0, "plate")
    # Then: the tops are the centres + r e_z, the actor is left out
    np.testing.assert_allclose(top_points(g), [[0.02, 0.02, 0.03], [0.08, 0.02, 0.06]], atol=1e-15)
    assert _top(g) == pytest.approx(0.06)
    assert _top_in(g, np.array([0.0, 0.0, 0.0]), np.array([0.05, 0.05, 1.0])) == pytest.approx(0.03)


def test_polyhedra_of_a_mixed_state_are_its_last_bodies():
    from demcli.engine.actors import add_actor, box_polyhedron
    from demcli.state.polyhedra import first_polyhedral_body, world_vertices
    from test_mixed_scene import sphere_groups

    g = add_actor(sphere_groups([[0.0, 0.0, 0.01]] * 3), box_polyhedron([0.1, 0.1, 0.02]), [0.5, 0.0, 0.3], 7800.0,
                  0, "plate")
    st = State(groups=g)
    # Then: the plate is body 3 and its vertices are drawn there; an extra polyhedron row is a state error
    assert first_polyhedral_body(st) == 3
    v, owner = world_vertices(st)
    assert owner.tolist() == [3] * 8
    np.testing.assert_allclose(v.mean(axis=0), [0.5, 0.0, 0.3], atol=1e-12)
    from demcli.state.fields import check

    def problems(groups):  # of the polyhedra rows (the groups lack the meta a stage writes)
        return [p for p in check(State(groups=groups)) if "polyhedra" in p and "n_m" not in p]

    assert problems(g) == []
    bad = {**g, "polyhedra": {k: np.concatenate([v_] * 5) for k, v_ in g["polyhedra"].items()}}
    assert problems(bad) == ["'polyhedra/shape' has 5 polyhedra but the state has 4 bodies"]
    no_spheres = {k: v_ for k, v_ in g.items() if k != "spheres"}
    assert problems(no_spheres) == ["'polyhedra/shape' has 1 polyhedra for 4 bodies and there are no spheres: "
                                    "3 bodies have no shape"]


def test_what_a_clump_bed_takes():
    from demcli.config.schema import Node
    from demcli.stages.ballast.box import _actor_scene_check
    from demcli.stages.base import load_case

    # Given: the sleeper stage on a clump bed, with shoulders asked for and rolling resistance
    case = load_case(SMOKE)
    cfg = case.stages[6]
    cfg = Node({**dict(cfg), "shoulders": Node({**dict(cfg.shoulders), "fill": True}),
                "physics": Node({**dict(cfg.physics), "rolling_resistance": True})})
    reports = []

    def report(key, rule, value=None):
        reports.append((key, rule))

    _actor_scene_check(cfg, case, 6, {"bodies/*", "spheres/*", "library/*", "gradation/*"}, report)
    # Then: the shoulders are refused (they are drawn as polyhedra), rolling resistance is not (spheres roll)
    assert reports == [("shoulders.fill", "the shoulder ballast is drawn as polyhedra, and this bed is made of "
                                          "spheres or clumps (set shoulders.fill: false)")]
    # and on a scene with polyhedra the shoulders are fine (rolling resistance too: the scene may be a clump bed
    # with its plate; a polyhedral bed refuses it when the stage starts and knows the bodies)
    reports.clear()
    _actor_scene_check(cfg, case, 6, {"bodies/*", "polyhedra/*", "library/*", "gradation/*"}, report)
    assert reports == []
    # and the whole case says so at demcli check (here the library, which clumpify does not carry, is missing too)
    result = CliRunner().invoke(cli, ["check", str(SMOKE), "--set", "stages.6.shoulders.fill=true"])
    assert result.exit_code == 2 and "shoulders.fill" in result.output, result.output


def test_planar_and_bonds_are_refused_in_a_mixed_scene():
    from demcli.effects import shape_refusals

    refused = {spec.name for spec, _ in shape_refusals(["planar", "bonds", "rolling_resistance", "friction"],
                                                        ("mixed",))}
    assert refused == {"planar", "bonds"}
