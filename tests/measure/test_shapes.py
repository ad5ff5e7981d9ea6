"""The measures on polyhedra and bonds (issue #33 items 1-2): two cubes pressed together through
their faces, their contact taken from the exact overlap the engine uses (contact_rows); bonded
spheres, whose bonds are contacts with their state."""

from types import SimpleNamespace

import numpy as np
import pytest

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls
from demcli.geometry import convex_hull
from demcli.measure.contacts import contact_set
from demcli.measure.forcechain import force_chain_mesh
from demcli.measure.probe import MeasureProbe


def _place(s):
    """The world vertices and face planes of unrotated bodies (what the engine's place pass
    writes): template vertices + x, template normals, offsets + n . x."""
    vs, verts, fs, fvs, fv, fn, fo = s.shapes
    wvert, wnorm, woff, _ = s.world
    for b, k in enumerate(s.shape):
        wvert[s.bvstart[b]:s.bvstart[b + 1]] = verts[vs[k]:vs[k + 1]] + s.x[b]
        wnorm[s.bfstart[b]:s.bfstart[b + 1]] = fn[fs[k]:fs[k + 1]]
        woff[s.bfstart[b]:s.bfstart[b + 1]] = fo[fs[k]:fs[k + 1]] + fn[fs[k]:fs[k + 1]] @ s.x[b]


def test_two_cubes_pressed_face_to_face():
    from demcli.engine.poly_shape import polyhedra_groups

    # Given two unit cubes, the upper one 0.98 above the lower (an overlap 0.02 deep), pressed by F
    cube = convex_hull(np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)], float))
    f = 50.0
    groups = polyhedra_groups([cube, cube], 2500.0, x=[[0, 0, 0], [0, 0, 0.98]], q=[[1, 0, 0, 0]] * 2)
    groups["body_contacts"] = {"i": np.array([0]), "j": np.array([1]), "force": np.array([[0.0, 0.0, -f]]),
                               "depth": np.array([0.02])}
    s = System(groups, [Material("rock", 2500.0)], ContactModel(), make_plan([], polyhedra=True), Walls(),
               Dynamics(), dt=1.0)
    _place(s)
    c = contact_set(s)
    # Then the contact is the overlap's centroid (z = 0.49) with its area normal (-z, from 1 to 0)
    assert (c.a.tolist(), c.b.tolist()) == ([0], [1])
    assert c.point[0] == pytest.approx([0, 0, 0.49], abs=1e-12)
    assert c.normal[0] == pytest.approx([0, 0, -1], abs=1e-12) and c.normal_force()[0] == pytest.approx(f)
    # and a box holding both cubes (V = 8) has sigma_zz V = (z_0 - z_1) F_0z = 0.98 F, compression positive
    row = MeasureProbe(s, [SimpleNamespace(type="box", name="b", min=(-1, -1, -1), max=(1, 1, 1))]).rows(s)["b"]
    assert row["sigma_zz"] * 8 == pytest.approx(0.98 * f, rel=1e-12)
    # (the box cuts the upper cube at z = 1: 1 + 0.52 of solid, exactly)
    assert row["fabric_zz"] == pytest.approx(1.0, rel=1e-15) and row["solid_fraction"] == pytest.approx(1.52 / 8,
                                                                                                       rel=1e-12)
    # a box of the lower cube's centre alone (V = 2 x 2 x 1.4) counts its side: (0 - 0.49) (-F) / V
    low = MeasureProbe(s, [SimpleNamespace(type="box", name="b", min=(-1, -1, -1), max=(1, 1, 0.4))]).rows(s)["b"]
    assert low["bodies"] == 1 and low["sigma_zz"] * 5.6 == pytest.approx(0.49 * f, rel=1e-12)
    # And the force chain is one line from centre to centre
    mesh = force_chain_mesh(s.x, s.body_id, c)
    assert mesh.points.tolist() == [[0, 0, 0], [0, 0, 0.98]] and mesh.cell_data["normal_force"][0][0] == pytest.approx(f)


def test_bonds_are_contacts_with_their_state_and_force(make_system):
    from demcli.engine.bonds import PARAM_NAMES, model_row
    from demcli.kernels import bonds as B

    # Given three spheres in a row along x (r = 1, touching): 0-1 held by a contact bond pulled apart
    # with T, 1-2 an ordinary contact pushed with F
    t, f = 4.0, 10.0
    n = 2
    hist = {name: np.zeros((n, 3)) if name in ("force_s", "moment_b", "kelvin_s") else np.zeros(n)
            for name in ("force_n", "force_s", "moment_t", "moment_b", "kelvin_n", "kelvin_s", "separation",
                         "overlap0")}
    bonds = {"bonds": {"i": np.array([0, 1]), "j": np.array([1, 2]), "model": np.zeros(2, np.int64),
                       "state": np.array([B.INTACT, B.BROKEN_TENSION], np.int8), **hist},
             "bond_models": {"kind": np.array(["contact_bond"], object), "materials": np.array([[0, 0]]),
                             "param_names": np.array(PARAM_NAMES, object),
                             "params": model_row("contact_bond", kn=1e5, ks=1e5)[None, :]}}
    s = make_system([[0, 0, 0], [2, 0, 0], [4, 0, 0]], np.ones(3), [(1, 2)], [(-f, 0, 0)], [], Walls(),
                    bonds=bonds)
    s._bond_arrays[7][0] = (t, 0.0, 0.0)  # the force the bond pass applied on 0: towards 1
    c = contact_set(s)
    # Then the set holds the contact, then the intact bond (the broken, unseated one is gone)
    assert c.bond.tolist() == [-1, B.INTACT] and c.a.tolist() == [1, 0] and c.b.tolist() == [2, 1]
    assert c.normal_force().tolist() == [f, -t]
    assert c.point[1].tolist() == [1.0, 0, 0]
    # and a box holding all three has sigma_xx V = (x_1 - x_2) (-F) + (x_0 - x_1) T = 2 F - 2 T
    row = MeasureProbe(s, [SimpleNamespace(type="box", name="b", min=(-2, -2, -2), max=(6, 2, 2))]).rows(s)["b"]
    assert row["sigma_xx"] * 128 == pytest.approx(2 * f - 2 * t, rel=1e-12)
    # the force chain carries the bond state: -1 for the contact, 0 for the intact bond
    mesh = force_chain_mesh(s.x, s.body_id, c)
    assert mesh.cell_data["bond_state"][0].tolist() == [-1, 0]
