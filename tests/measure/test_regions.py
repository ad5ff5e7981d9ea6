"""Measurement regions (issue #33 item 1): which bodies each region type holds, its volume, the
Love-Weber stress, fabric and coordination of hand-built scenes with known answers, and the
config rules (exit code 2)."""

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from demcli.cli import cli
from demcli.measure.contacts import contact_set
from demcli.measure.probe import MeasureProbe
from demcli.measure.regions import Region
from demcli.measure.tensors import anisotropy, fabric, invariants, love_weber, sides


def _region(kind, **kw):
    return Region(SimpleNamespace(type=kind, name=kind, **kw))


def test_each_region_type_holds_the_centres_inside_and_on_its_boundary():
    # Given points on the axes at 0.9 and 1.1 and the corner diagonal, and regions of size about 1
    pts = np.array([[0.9, 0, 0], [1.1, 0, 0], [0, 0, 0.9], [0, 0, 1.1], [0.6, 0.6, 0.6], [1.0, 0, 0]])
    ball = _region("sphere", centre=(0, 0, 0), radius=1.0)
    box = _region("box", min=(-1, -1, -1), max=(1, 1, 1))
    tube = _region("cylinder", base=(0, 0, -1), axis=(0, 0, 2), radius=1.0, span=(0.5, 2.0))
    # Then each holds the points inside it or on its boundary
    assert ball.inside(pts).tolist() == [True, False, True, False, False, True]
    assert box.inside(pts).tolist() == [True, False, True, False, True, True]
    # the cylinder runs from z = -0.5 to 1 along its normalised axis, radius 1 about the z axis
    assert tube.inside(pts).tolist() == [True, False, True, False, True, True]
    assert tube.inside([[0, 0, -0.6]]).tolist() == [False]
    # And their volumes are the closed forms
    assert ball.volume() == pytest.approx(4 / 3 * math.pi, rel=1e-15)
    assert box.volume() == 8.0
    assert tube.volume() == pytest.approx(1.5 * math.pi, rel=1e-15)
    # an `all` region is the box it is given at each record
    whole = _region("all", around="bodies")
    whole.set_box((0, 0, 0), (2, 3, 4))
    assert whole.volume() == 24.0 and whole.inside(pts).tolist() == [True, True, True, True, True, True]


def test_a_simple_cubic_lattice_under_pressure_gives_the_analytic_stress_and_fabric(make_lattice):
    # Given a simple cubic lattice of 4^3 spheres (d = 2 mm) in a box of walls, every contact pushing
    # with P d^2 (P = 100 kPa): the stress is P I everywhere
    d, p = 2e-3, 1e5
    s = make_lattice(4, d, p)
    specs = [SimpleNamespace(type="all", name="whole", around="walls"),
             SimpleNamespace(type="box", name="core", min=(d,) * 3, max=(3 * d,) * 3),
             SimpleNamespace(type="sphere", name="ball", centre=(2 * d,) * 3, radius=1.2 * d)]
    rows = MeasureProbe(s, specs).rows(s)
    for name in ("whole", "core"):
        row = rows[name]
        # Then the Love-Weber stress of the whole box (walls' side left out) and of a box of whole
        # cells (8 bodies, each side d/2 x P d^2) is P I to round-off, p = P and q = 0
        for c in ("xx", "yy", "zz"):
            assert row[f"sigma_{c}"] == pytest.approx(p, rel=1e-12), (name, c)
        for c in ("xy", "xz", "yz"):
            assert abs(row[f"sigma_{c}"]) < 1e-9 * p
        assert row["pressure"] == pytest.approx(p, rel=1e-12) and row["deviator"] < 1e-9 * p
        # the fabric of the six normals of each body is I / 3 (isotropic: a = 0), weighted or not
        for prefix in ("fabric", "fabric_f"):
            assert [row[f"{prefix}_{c}"] for c in ("xx", "yy", "zz", "xy", "xz", "yz")] == pytest.approx(
                [1 / 3] * 3 + [0] * 3, abs=1e-15)
        assert row["anisotropy"] < 1e-12 and row["anisotropy_f"] < 1e-12
        # every body has 6 contacts (walls counted), none rattles; the box solid fraction is pi / 6
        assert (row["mean_coordination"], row["mechanical_coordination"], row["rattler_fraction"]) == (6, 6, 0)
        assert row["solid_fraction"] == pytest.approx(math.pi / 6, rel=1e-13)
    assert (rows["whole"]["bodies"], rows["core"]["bodies"]) == (64, 8)
    # And the sphere region (radius 1.2 d about a lattice node) holds the 8 bodies around it: its
    # centre-count solid fraction is 8 spheres over its volume
    ball = rows["ball"]
    assert ball["bodies"] == 8
    assert ball["solid_fraction"] == pytest.approx(8 * (math.pi / 6) * d ** 3 / (4 / 3 * math.pi * (1.2 * d) ** 3))
    assert ball["sigma_zz"] == pytest.approx(p * 8 * d ** 3 / (4 / 3 * math.pi * (1.2 * d) ** 3), rel=1e-12)


def test_clump_contacts_act_on_their_bodies_and_count_once_for_coordination(make_system):
    # Given two dumbbell clumps (members at x = +-a, radius r) stacked along z, touching at both
    # member pairs with force F each, the lower one on a floor (force F on each member), and a
    # region holding both: sigma_zz V = 2 F (2 r) (pairs) + 2 F r (floor) = 6 F r
    from demcli.engine.system import Walls

    a, r, f = 0.5, 0.5, 3.0
    x = np.array([[0.0, 0.0, r], [0.0, 0.0, 3 * r]])
    off = np.array([[-a, 0, 0], [a, 0, 0]] * 2)
    floor = Walls.fixed_planes([(0, 0, 0)], [(0, 0, 1)])
    s = make_system(x, np.full(4, r), [(0, 2), (1, 3)], [(0, 0, -f), (0, 0, -f)], [(0, 0, (0, 0, f)),
                                                                                     (1, 0, (0, 0, f))],
                    floor, sbody=[0, 0, 1, 1], soff=off)
    row = MeasureProbe(s, [SimpleNamespace(type="box", name="b", min=(-2, -2, -1), max=(2, 2, 3))]).rows(s)["b"]
    # Then the stress follows from the contact points and the bodies' centres, the fabric is all z
    assert row["sigma_zz"] * 64 == pytest.approx(6 * f * r, rel=1e-12)
    assert abs(row["sigma_xz"]) < 1e-12 and row["fabric_zz"] == pytest.approx(1.0, rel=1e-15)
    # the two member contacts of the clump pair are one contact: clump 0 has 1 + floor, clump 1 has 1
    # (a rattler: fewer than 2), which then leaves clump 0 with only the floor: both rattle
    assert row["mean_coordination"] == 1.5 and row["rattler_fraction"] == 1.0
    assert math.isnan(row["mechanical_coordination"])


def test_rattlers_are_removed_iteratively_and_walls_count():
    # Given a chain floor - A - B - C (C touches only B) and D touching nothing, plus E and F, each
    # touching the floor, a side wall and each other
    from demcli.stages.packing_record import contact_counts

    pairs = [(0, 1), (1, 2), (4, 5)]
    walls = [0, 4, 4, 5, 5]
    z0, z, rattler = contact_counts(6, pairs, walls, 2, np.zeros(6, bool))
    # Then C (1 contact) goes, then B (left with A only), then A (left with the floor only); D has
    # none; E and F keep 3 each: walls count, and bodies left with enough contacts stay
    assert rattler.tolist() == [True, True, True, True, False, False]
    assert z0.tolist() == [2, 2, 1, 0, 3, 3] and z[4:].tolist() == [3, 3]


def test_tensor_helpers_on_known_answers():
    # a triaxial stress diag(3, 1, 1): p = 5/3, q = 2; a uniaxial fabric (all normals along z):
    # a_ij = 15/2 diag(-1/3, -1/3, 2/3), a = a_zz - a_xx = 15/2
    p, q = invariants(np.diag([3.0, 1.0, 1.0]))
    assert p == pytest.approx(5 / 3) and q == pytest.approx(2.0)
    assert anisotropy(fabric([[0, 0, 1.0], [0, 0, -1.0]])) == pytest.approx(7.5, rel=1e-15)
    # normals spread evenly over the sphere (a Fibonacci set of 20 000) are isotropic to 1e-3
    k = np.arange(20000) + 0.5
    z = 1 - 2 * k / 20000
    t = math.pi * (1 + 5 ** 0.5) * k
    n = np.stack([np.sqrt(1 - z * z) * np.cos(t), np.sqrt(1 - z * z) * np.sin(t), z], axis=1)
    assert anisotropy(fabric(n)) < 1e-3
    # an empty region: NaN stress
    assert np.isnan(love_weber(np.zeros((0, 3)), np.zeros((0, 3)), 0.0)).all()


def test_contact_sides_from_a_scene(make_lattice):
    # each pair of the 2^3 lattice gives two sides, each wall contact one: 12 pairs, 24 wall contacts
    s = make_lattice(2)
    c = contact_set(s)
    sd = sides(c, s.x)
    assert (len(c.a), len(sd.body)) == (36, 48)
    # every branch runs from the contact point to the body's centre: half a diameter along the normal
    assert np.allclose(np.linalg.norm(sd.branch, axis=1), 0.5)
    assert np.allclose(np.abs(np.einsum("ij,ij->i", sd.branch, sd.normal)), 0.5)


# ---- config --------------------------------------------------------------------------------------

# the beads smoke case less its settle stage's output line: the line under test takes its place
CASE = (Path(__file__).resolve().parents[2] / "cases" / "smoke" / "beads.yaml").read_text().replace(
    "    output: {records: 20, snapshots: 3}\n", "")
LINE = CASE.count("\n") + 1  # the line the key under test is on

BAD = {
    "measure: [{name: a, type: cube, min: [0, 0, 0], max: [1, 1, 1]}]": "stages[1].measure[0].type: unknown type",
    "measure: [{name: a, type: sphere, centre: [0, 0, 0], radius: -1 mm}]": "stages[1].measure[0].radius: must be > 0",
    "measure: [{name: a, type: box, min: [0, 0, 0], max: [1, -1, 1]}]": "stages[1].measure[0].max[1]: must be > min",
    "measure: [{name: a, type: cylinder, base: [0, 0, 0], radius: 1 mm, span: [2 mm, 1 mm]}]":
        "stages[1].measure[0].span[1]: must be > span.0",
    "measure: [{name: a, type: cylinder, base: [0, 0, 0], axis: [0, 0, 0], radius: 1 mm, span: [0, 1 mm]}]":
        "stages[1].measure[0].axis: must not be the zero vector",
    "measure: [{name: a, type: all, centre: [0, 0, 0]}]": "stages[1].measure[0].centre: unknown key",
    "measure: [{name: a, type: all}, {name: a, type: all}]": "stages[1].measure[1].name: duplicate name",
    "measure: [{name: 2nd, type: all}]": "stages[1].measure[0].name: must match",
    "output: {fields: {width: 0}}": "stages[1].output.fields.width: must be > 0",
    "output: {fields: {width: 1 mm, kernel: cubic}}": "stages[1].output.fields.kernel: must be one of",
    "output: {fields: {width: 1 mm, min: [0, 0, 0]}}": "stages[1].output.fields.max: give both min and max",
    "output: {force_chains: 3}": "stages[1].output.force_chains: must be",
    "output: {snapshots: 0, force_chains: true}": "stages[1].output.force_chains: is written at every snapshot",
    "output: {snapshots: 0, fields: {width: 1 mm}}": "stages[1].output.fields: is written at every snapshot",
}


@pytest.mark.parametrize("line", list(BAD))
def test_bad_measure_settings_are_refused_with_exit_code_2(tmp_path, line):
    path = tmp_path / "case.yaml"
    path.write_text(CASE + "    " + line + "\n")
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert BAD[line] in result.output, result.output
    assert f"case.yaml:{LINE}: " in result.output  # the file and the line of the key


def test_good_measure_settings_pass_check(tmp_path):
    path = tmp_path / "case.yaml"
    path.write_text(CASE + "    measure: [{name: core, type: sphere, centre: [5 mm, 5 mm, 5 mm], radius: 3 mm},\n"
                           "              {name: tube, type: cylinder, base: [5 mm, 5 mm, 0], radius: 4 mm, "
                           "span: [0, 10 mm]},\n"
                           "              {name: all, type: all, around: walls}]\n"
                           "    output: {force_chains: true, fields: {width: 2 mm, kernel: lucy}}\n")
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("line, refused", [("measure: [{name: a, type: all}]", True),
                                           ("output: {records: 30, snapshots: 2, fields: {width: 1 mm}}", True),
                                           ("output: {records: 30, snapshots: 2, force_chains: true}", False)])
def test_a_planar_case_takes_force_chains_but_no_per_volume_measure(tmp_path, line, refused):
    # Given the planar smoke case (disks) with a region, fields or force chains in its settle stage
    text = (Path(__file__).resolve().parents[2] / "cases" / "smoke" / "planar.yaml").read_text()
    path = tmp_path / "case.yaml"
    path.write_text(text.replace("    output: {records: 30, snapshots: 2}\n", "") + "    " + line + "\n")
    result = CliRunner().invoke(cli, ["check", str(path)])
    # Then regions and fields (per volume) are refused at check, exit code 2; force chains pass
    assert result.exit_code == (2 if refused else 0), result.output
    assert ("is per volume, for 3D cases" in result.output) == refused
