"""Builders for small engine scenes (spheres, plane walls, rigid clumps).

Tests have no packages, so the builders are handed out as fixtures that return the
builder functions.
"""

import math

import numpy as np
import pytest

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls

NO_GRAVITY = (0.0, 0.0, 0.0)


def sphere_mass(radius, density):
    return density * 4.0 / 3.0 * math.pi * radius ** 3


def plane_walls(points, normals, material=0):
    """Fixed plane walls (kind 0) through ``points`` with unit ``normals`` into the domain."""
    return Walls.fixed_planes(points, normals, material)


def sphere_system(x, v, radius, materials, model, effects=(), walls=None, omega=None, gravity=NO_GRAVITY,
                  density=None, force=None, dt_factor=0.01, material=None, **dyn):
    """Spheres-only System (sphere i is body i) with dt = ``dt_factor`` x critical step."""
    x = np.asarray(x, float).reshape(-1, 3)
    n = len(x)
    r = np.broadcast_to(np.asarray(radius, float), (n,)).copy()
    rho = materials[0].density if density is None else density
    m = rho * 4.0 / 3.0 * np.pi * r ** 3
    bodies = {"x": x, "v": np.asarray(v, float).reshape(n, 3),
              "omega": np.zeros((n, 3)) if omega is None else np.asarray(omega, float).reshape(n, 3),
              "q": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "mass": m,
              "inertia": np.repeat((0.4 * m * r * r)[:, None], 3, axis=1),
              "flags": np.zeros(n, np.int8), "id": np.arange(n, dtype=np.int64)}
    if force is not None:
        bodies["force"] = np.asarray(force, float).reshape(n, 3)
    spheres = {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)), "radius": r,
               "material": np.zeros(n, np.int64) if material is None else np.asarray(material, np.int64)}
    walls = Walls() if walls is None else walls
    plan = make_plan(list(effects), walls=len(walls) > 0)
    s = System({"bodies": bodies, "spheres": spheres}, materials, model, plan, walls,
               Dynamics(gravity=gravity, **dyn), dt=1.0)
    s.dt = dt_factor * s.critical_dt()
    return s


def clump_system(inertia, omega, q=(1.0, 0.0, 0.0, 0.0), mass=1.0, radius=0.05, dt=1e-4, angmom=None):
    """One rigid body with principal ``inertia`` and a single member sphere at its centre."""
    bodies = {"x": np.zeros((1, 3)), "v": np.zeros((1, 3)), "omega": np.asarray(omega, float).reshape(1, 3),
              "q": np.asarray(q, float).reshape(1, 4), "mass": np.array([mass]),
              "inertia": np.asarray(inertia, float).reshape(1, 3), "flags": np.zeros(1, np.int8),
              "id": np.zeros(1, np.int64)}
    if angmom is not None:
        bodies["angmom"] = np.asarray(angmom, float).reshape(1, 3)
    spheres = {"body": np.zeros(1, np.int64), "offset": np.zeros((1, 3)), "radius": np.array([radius]),
               "material": np.zeros(1, np.int64)}
    mats = [Material("m", 1000.0)]
    return System({"bodies": bodies, "spheres": spheres}, mats, ContactModel(), make_plan([], clumps=True),
                  Walls(), Dynamics(gravity=NO_GRAVITY), dt=dt)


class Builders:
    Material = Material
    ContactModel = ContactModel
    Dynamics = Dynamics
    NO_GRAVITY = NO_GRAVITY
    sphere_mass = staticmethod(sphere_mass)
    plane_walls = staticmethod(plane_walls)
    sphere_system = staticmethod(sphere_system)
    clump_system = staticmethod(clump_system)


@pytest.fixture(autouse=True, scope="session")
def _one_thread():
    """These scenes have 1-30 spheres: one thread is fastest and immune to a busy machine
    (results do not depend on the thread count: the gather is race-free and ordered)."""
    from demcli.jit import set_threads

    import numba

    before = numba.get_num_threads()
    set_threads(1)
    yield
    set_threads(before)


@pytest.fixture
def build():
    """Scene builders: ``build.sphere_system(...)``, ``build.plane_walls(...)``, ``build.clump_system(...)``."""
    return Builders
