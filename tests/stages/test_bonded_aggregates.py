"""Bonded aggregates (issue #32 item 1; demcli/stages/asphalt/bonded.py, docs/asphalt_lab.md
"Bonded aggregates"): releasing a clump into bonded lattice balls, the bond from the stone's
modulus and tensile strength checked on a lattice cube pulled apart, and the config's errors."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from demcli.cli import cli
from demcli.engine.bonds import model_row
from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls
from demcli.kernels import bonds as B
from demcli.kernels import layout as K
from demcli.stages.asphalt.bonded import bond_members, bond_parameters, release, tensile_strength

ROOT = Path(__file__).resolve().parents[2]
BONDED_SMOKE = ROOT / "cases" / "smoke" / "marshall_ac13_3d_idt_bonded.yaml"
R = 0.5e-3           # lattice ball radius [m] (spacing L = 2 R)
RHO = 2640.0         # stone density [kg/m^3]
E, NU = 50e9, 0.25   # stone Young's modulus [Pa] and Poisson's ratio
SIGMA_T = 10e6       # stone tensile strength [Pa]


def cube_clump(n, omega=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0)):
    """State groups of one aggregate: an n x n x n simple cubic lattice of balls (spacing 2 R) as
    a rigid clump at the origin (mass model cells: each ball its cell's mass RHO (2R)^3)."""
    a = 2.0 * R
    g = np.arange(n) * a
    pts = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    off = pts - pts.mean(axis=0)
    m_e = RHO * a ** 3
    inertia = m_e * (np.sum(off ** 2) - np.sum(off ** 2, axis=0)) + len(off) * m_e * a * a / 6.0
    bodies = {"x": pts.mean(axis=0)[None, :], "v": np.array([v], float), "q": np.array([[1.0, 0, 0, 0]]),
              "omega": np.array([omega], float), "mass": np.array([m_e * len(off)]), "inertia": inertia[None, :],
              "id": np.zeros(1, np.int64), "flags": np.zeros(1, np.int8)}
    spheres = {"body": np.zeros(len(off), np.int64), "offset": off, "radius": np.full(len(off), R),
               "material": np.zeros(len(off), np.int64)}
    aggregates = {"body": np.zeros(1, np.int64), "ball_radius": np.float64(R), "mass_model": np.array("cells", object)}
    return {"bodies": bodies, "spheres": spheres, "aggregates": aggregates}


def test_release_keeps_mass_momentum_and_positions():
    # Given a spinning, moving 3 x 3 x 3 clump
    groups = cube_clump(3, omega=(1.0, -2.0, 0.5), v=(0.1, 0.0, -0.2))
    out, agg = release(groups)
    b, ob = out["bodies"], groups["bodies"]
    # Then every ball is a body of its own, at its place, with the clump's point velocity v + w x d,
    # and the balls' mass, momentum and (about the clump's centre) angular momentum are the clump's
    d = groups["spheres"]["offset"]
    assert np.all(agg == 0) and np.array_equal(out["spheres"]["body"], np.arange(27)) and "aggregates" not in out
    assert np.allclose(b["x"], ob["x"] + d, rtol=0, atol=1e-15)
    assert b["mass"].sum() == pytest.approx(ob["mass"][0], rel=1e-14)
    assert np.allclose((b["mass"][:, None] * b["v"]).sum(axis=0), ob["mass"][0] * ob["v"][0], rtol=1e-12)
    spin = np.sum(b["mass"][:, None] * np.cross(d, b["v"] - ob["v"][0]) + b["inertia"] * b["omega"], axis=0)
    assert np.allclose(spin, ob["inertia"][0] * ob["omega"][0], rtol=1e-12)


def test_bond_parameters_follow_the_documented_relation():
    # sigma_c = 4 sigma_t / (pi lambda^2), kn_b = 2 E / (pi lambda^2 r), ks_b = kn_b / (2 (1 + nu))
    p = bond_parameters(E, NU, R, SIGMA_T, shear_ratio=0.5, radius_multiplier=0.8)
    assert p["normal_strength"] == pytest.approx(4 * SIGMA_T / (math.pi * 0.64), rel=1e-14)
    assert p["shear_strength"] == pytest.approx(0.5 * p["normal_strength"], rel=1e-14)
    assert p["bond_kn"] * math.pi * (0.8 * R) ** 2 == pytest.approx(E * 2 * R, rel=1e-14)   # k_n = E L
    assert p["bond_ks"] == pytest.approx(p["bond_kn"] / 2.5, rel=1e-14)

    class Crushing:   # a grain of 10 mm split at 1 kN: sigma_t = F / d^2 = 10 MPa
        tensile_strength = None
        crushing = type("C", (), {"force": 1e3, "size": 0.01})

    assert tensile_strength(Crushing) == pytest.approx(10e6, rel=1e-14)


def pulled_cube(n, speed):
    """The n^3 clump released and bonded (bond of E, NU, SIGMA_T), its face x = 0 held and its
    face x = (n - 1) L pulled along +x at ``speed`` [m/s]; local damping 0.7 on the balls between."""
    out, agg = release(cube_clump(n))
    plan = make_plan(["bonds", "local_damping"], bonds=True)
    s = System(out, [Material("stone", RHO, friction=0.0)], ContactModel(law="linear", kn=1e6), plan, Walls(),
               Dynamics(gravity=(0.0, 0.0, 0.0), local_damping=0.7), dt=1.0)
    n_bonds = bond_members(s, agg, bond_parameters(E, NU, R, SIGMA_T))
    x = s.x[:, 0]
    lo, hi = x < 0.5 * R, x > x.max() - 0.5 * R
    s.bflags[lo | hi] = K.FIX_TRANSLATION | K.FIX_ROTATION
    s.v[hi, 0] = speed
    s.dt = 0.5 * s.critical_dt()
    return s, n_bonds, hi


def test_lattice_cube_pulled_apart_fails_at_the_stone_tensile_strength():
    # Given a 4 x 4 x 4 aggregate released into bonded balls (r = 0.5 mm), one face held and the
    # opposite one pulled at 1 mm/s (failure strain sigma_t / E = 2e-4 reached in about 600 us,
    # some 300 periods of the cube's axial mode: quasi-static)
    n, speed = 4, 1e-3
    s, n_bonds, hi = pulled_cube(n, speed)
    assert n_bonds == 3 * n * n * (n - 1)   # every face-neighbour pair, nothing else
    inside = s.bonds.internal()
    assert inside.all() and s.bonds.materials.tolist() == [[-1, -1]]
    last = np.isin(s.bonds.j, np.flatnonzero(hi)) & ~np.isin(s.bonds.i, np.flatnonzero(hi))  # into the pulled face
    t, load = [], []
    while s.bonds.counts()["intact"] == n_bonds and s.step < 20000:
        assert s.advance(10)[0] == K.OK
        t.append(s.time)
        load.append(float(-s.bonds.hist[last, B.H_FN].sum()))   # tension across the pulled face [N]
    t, load = np.array(t), np.array(load)
    # Then the first bonds break at the load of the stone's tensile strength on the cube's section,
    # P = sigma_t (n L)^2 (= n^2 sigma_c A_b), within 1 % (measured: see the print)
    area = (n * 2 * R) ** 2
    print(f"peak {load.max():.5g} N against sigma_t (nL)^2 = {SIGMA_T * area:.5g} N "
          f"({load.max() / (SIGMA_T * area) - 1:+.2e}); steps {s.step}")
    assert load.max() == pytest.approx(SIGMA_T * area, rel=0.01)
    # in tension, all the n^2 bonds of one layer together (the columns are alike)
    c = s.bonds.counts()
    assert c["broken_shear"] == 0 and c["broken_tension"] % (n * n) == 0 and c["broken_tension"] > 0
    assert s.bonds.internal_counts() == c   # all of them inside the aggregate
    # and before that the cube stretched as the stone: P / u = E (nL)^2 / ((n - 1) L) within 2 %
    half = load < 0.5 * load.max()
    slope = np.polyfit(speed * t[half & (load > 0.1 * load.max())], load[half & (load > 0.1 * load.max())], 1)[0]
    stiff = E * area / ((n - 1) * 2 * R)
    print(f"stiffness {slope:.5g} N/m against E (nL)^2 / ((n-1) L) = {stiff:.5g} N/m ({slope / stiff - 1:+.2e})")
    assert slope == pytest.approx(stiff, rel=0.02)


def _check(tmp_path, aggregates):
    """`demcli check` of the bonded smoke case with the mastic stage's ``aggregates`` replaced."""
    case = yaml.safe_load(BONDED_SMOKE.read_text())
    next(st for st in case["stages"] if st["type"] == "mastic")["aggregates"] = aggregates
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(case))
    return CliRunner().invoke(cli, ["check", str(path)])


@pytest.mark.parametrize("aggregates, words", [
    ({"model": "bonded"}, ["aggregates.tensile_strength", "exactly one of tensile_strength and crushing"]),
    ({"model": "bonded", "tensile_strength": "10 MPa", "crushing": {"force": "1 kN", "size": "10 mm"}},
     ["aggregates.tensile_strength", "exactly one"]),
    ({"model": "bonded", "tensile_strength": "-1 MPa"}, ["aggregates.tensile_strength", "-1"]),
    ({"model": "glued"}, ["aggregates.model", "unknown model", "glued"]),
    ({"model": "rigid", "tensile_strength": "10 MPa"}, ["aggregates.tensile_strength"]),
])
def test_bad_aggregates_config_is_refused(tmp_path, aggregates, words):
    res = _check(tmp_path, aggregates)
    assert res.exit_code == 2, res.output
    for w in words:
        assert w in res.output, res.output


def test_rigid_is_the_default(tmp_path):
    # the shipped idt smoke case, aggregates not given, and aggregates: {model: rigid} check alike
    assert _check(tmp_path, {"model": "rigid"}).exit_code == 0
