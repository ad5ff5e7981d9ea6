"""Scene builders for the stability suite (spheres, plane walls, convex polyhedra).

Tests have no packages, so the builders are handed out as the ``scene`` fixture.
``DEMCLI_STRESS=1`` (``make stress``) selects the long variants: ``scene.STRESS``.
"""

import os

import numpy as np
import pytest

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls

STRESS = os.environ.get("DEMCLI_STRESS") == "1"
G = 9.81


def planes(points, normals):
    """Fixed plane walls (kind 0) through ``points`` with unit ``normals`` into the domain."""
    return Walls.fixed_planes(points, normals)


def closed_box(side):
    """Six plane walls around the cube [0, side]^3."""
    return planes([[0, 0, 0], [side, 0, 0], [0, 0, 0], [0, side, 0], [0, 0, 0], [0, 0, side]],
                  [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])


def spheres(x, v, r, materials, model, effects=(), walls=None, dt_factor=0.2, **dyn):
    """Spheres-only System (sphere i is body i, material 0) with dt = dt_factor x critical."""
    x = np.asarray(x, float).reshape(-1, 3)
    n = len(x)
    r = np.broadcast_to(np.asarray(r, float), (n,)).copy()
    m = materials[0].density * 4 / 3 * np.pi * r ** 3
    groups = {"bodies": {"x": x, "v": np.asarray(v, float).reshape(n, 3), "omega": np.zeros((n, 3)),
                         "q": np.tile([1.0, 0, 0, 0], (n, 1)), "mass": m,
                         "inertia": np.repeat((0.4 * m * r * r)[:, None], 3, axis=1),
                         "flags": np.zeros(n, np.int8), "id": np.arange(n)},
              "spheres": {"body": np.arange(n), "offset": np.zeros((n, 3)), "radius": r,
                          "material": np.zeros(n, np.int64)}}
    walls = Walls() if walls is None else walls
    plan = make_plan(list(effects), walls=len(walls) > 0)
    s = System(groups, materials, model, plan, walls, Dynamics(**dyn), dt=1.0)
    s.dt = dt_factor * s.critical_dt()
    return s


def box(lx, ly, lz):
    """Box centred on the origin (m)."""
    from demcli.geometry import convex_hull

    return convex_hull(np.array([[i, j, k] for i in (-lx / 2, lx / 2) for j in (-ly / 2, ly / 2)
                                 for k in (-lz / 2, lz / 2)], float))


def quat(rotvec):
    """Quaternion (w, x, y, z) of a rotation vector [rad]."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_rotvec(rotvec).as_quat()
    return [w, x, y, z]


def polyhedra(*args, **kw):
    """System of ConvexPolyhedron bodies (one material) with dt = dt_factor x critical: the
    builder of tests/engine/test_polyhedra_dynamics.py (same keywords, ``density`` included)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "engine"))
    from test_polyhedra_dynamics import system

    return system(*args, **kw)


def mechanical_energy(s):
    """Kinetic + strain (polyhedra: estimated) + gravity [J]."""
    return s.kinetic_energy() + s.strain_energy() + s.gravity_potential()


def verlet_gain(omega_dt):
    """Worst kinetic-energy error of one linear-spring contact under velocity Verlet.

    Inside the contact, velocity Verlet conserves v^2 + omega^2 x^2 (1 - (omega dt)^2 / 4)
    exactly; entering and leaving the contact between two steps costs or gains up to
    about (omega dt)^2 / 4 of the kinetic energy, depending on where in the step the
    contact starts.
    """
    return omega_dt ** 2 / 4.0


class Scenes:
    STRESS = STRESS
    G = G
    Material = Material
    ContactModel = ContactModel
    planes = staticmethod(planes)
    closed_box = staticmethod(closed_box)
    spheres = staticmethod(spheres)
    box = staticmethod(box)
    quat = staticmethod(quat)
    polyhedra = staticmethod(polyhedra)
    mechanical_energy = staticmethod(mechanical_energy)
    verlet_gain = staticmethod(verlet_gain)


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    """Small scenes: one thread. Results do not depend on the thread count, and OpenMP threads
    spin at every barrier: on a busy machine two threads made the dense-start test 80 times
    slower (59 s against 0.7 s, measured while other runs held both cores)."""
    import numba

    from demcli.jit import set_threads

    before = numba.get_num_threads()
    set_threads(1)
    yield
    set_threads(before)


@pytest.fixture
def scene():
    """Scene builders: ``scene.spheres(...)``, ``scene.polyhedra(...)``, ``scene.planes(...)``, ..."""
    return Scenes

