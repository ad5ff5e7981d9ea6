"""Hard cases stay numerically stable (fast sizes; DEMCLI_STRESS=1 runs longer variants)."""

import math
import os

import numpy as np

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls
from demcli.kernels import layout as K
from demcli.kernels.walls import N_WPARAMS

STRESS = os.environ.get("DEMCLI_STRESS") == "1"


def spheres(x, v, r, mat, model, effects, walls=Walls(), **dyn):
    x = np.asarray(x, float)
    n = len(x)
    r = np.broadcast_to(np.asarray(r, float), (n,)).copy()
    m = mat[0].density * 4 / 3 * np.pi * r ** 3
    groups = {"bodies": {"x": x, "v": np.asarray(v, float), "omega": np.zeros((n, 3)),
                         "q": np.tile([1.0, 0, 0, 0], (n, 1)), "mass": m,
                         "inertia": np.repeat((0.4 * m * r * r)[:, None], 3, axis=1),
                         "flags": np.zeros(n, np.int8), "id": np.arange(n)},
              "spheres": {"body": np.arange(n), "offset": np.zeros((n, 3)), "radius": r,
                          "material": np.zeros(n, np.int64)}}
    plan = make_plan(effects, walls=len(walls) > 0)
    return System(groups, mat, model, plan, walls, Dynamics(**dyn), dt=1.0)


def floor(z=0.0):
    return Walls(name=["floor"], kind=np.zeros(1, np.int8), point=np.array([[0, 0, z]], float),
                 normal=np.array([[0, 0, 1.0]]), radius=np.zeros(1), v=np.zeros((1, 3)),
                 material=np.zeros(1, np.int64), control=np.zeros(1, np.int8), prm=np.zeros((1, N_WPARAMS)),
                 extent=np.array([[-1, -1, 0, 1, 1, 0]], float))


def lattice(n_side, spacing, r):
    g = np.arange(n_side) * spacing + r
    return np.array([[a, b, c] for c in g for b in g for a in g])


def test_very_stiff_contacts_with_the_automatic_step():
    # Given a column of touching steel-hard spheres (E = 4e11 Pa, as printed in seed 002) on a floor
    r = 0.02
    mat = [Material("ballast", 2600.0, young=4e11, poisson=0.3, friction=0.67, restitution=0.5)]
    x = lattice(3, 2 * r, r)
    s = spheres(x, np.zeros_like(x), r, mat, ContactModel(law="hertz_mindlin"), ["gravity", "friction"],
                walls=floor(), gravity=(0, 0, -9.81), local_damping=0.2, check_every=50)
    s.dt = 0.2 * s.critical_dt()
    s.ke_limit = 1e3 * (s.mass.sum() * 9.81 * 0.2)
    # When it runs (automatic dt = 0.2 x Rayleigh, ~1.4e-6 s)
    status, done = s.advance(200000 if STRESS else 20000)
    # Then no guard trips, overlaps stay tiny, and the column is at rest on the floor
    assert status == K.OK and np.isfinite(s.x).all()
    assert s.info[2] < 1e-4  # worst overlap / radius at the last check
    assert np.abs(s.v).max() < 1e-3


def test_fast_impact_on_a_wall_does_not_tunnel():
    # Given a 1 mm sphere at 50 m/s towards a floor
    r = 1e-3
    mat = [Material("m", 2500.0, young=5e10, poisson=0.25, friction=0.0, restitution=0.8)]
    s = spheres([[0, 0, 5 * r]], [[0, 0, -50.0]], r, mat, ContactModel(law="hertz_mindlin"), [], walls=floor())
    s.dt = 0.2 * s.critical_dt()
    # When it has had time to hit and fly back
    steps = int(math.ceil(2 * 4 * r / 50 / s.dt)) + 2000
    assert s.advance(steps)[0] == K.OK
    # Then it never crossed the wall and left upwards (the contact spans several steps)
    assert s.x[0, 2] > r
    assert s.v[0, 2] > 0.5 * 50


def test_dense_start_with_ten_percent_overlaps_relaxes_without_explosion():
    # Given 343 spheres on a lattice whose neighbours overlap by 10 % of the diameter
    r = 1e-3
    mat = [Material("m", 2500.0, young=1e8, poisson=0.3, friction=0.5, restitution=0.3)]
    n = 11 if STRESS else 7
    x = lattice(n, 1.8 * r, r)
    s = spheres(x, np.zeros_like(x), r, mat, ContactModel(law="hertz_mindlin"), ["friction"],
                local_damping=0.7, overlap_limit=0.5)
    s.dt = 0.2 * s.critical_dt()
    # When it relaxes
    status, _ = s.advance(5000)
    # Then no guard trips, nothing flies off (speeds stay below the elastic wave estimate of the
    # stored energy), and the overlaps have relaxed below 1 % of the radius
    assert status == K.OK
    m = s.mass[0]
    kn = 4 / 3 * (1e8 / (2 * (1 - 0.09))) * math.sqrt(r / 2) * (0.2 * r) ** 1.5  # F at 10 % overlap
    v_bound = math.sqrt(2 * 6 * 0.4 * kn * 0.2 * r / m)  # all six contacts' energy into one sphere
    assert np.abs(s.v).max() < v_bound
    s.advance(20000)
    assert s.info[2] < 0.01
