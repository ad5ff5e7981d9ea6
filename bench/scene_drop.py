"""The peers' sphere "drop"/"dense" scene (../shared/peers/common/drop_setup.py) as a System.

Same lattice, jitter, velocities (seeded RandomState 12345), box, linear spring-dashpot
(kn 1e5 N/m, kt kn/4, constant cn for e = 0.5, mu 0.5), gravity, dt 1e-6 s.
"""

import math

import numpy as np

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls
from demcli.state.order import cell_order, mean_spacing

D = 2.0e-3
RHO = 2650.0
KN = 1.0e5
SPACING = {"drop": 1.1 * D, "dense": 1.02 * D}
DIMS = {1000: (10, 10, 10), 10000: (20, 20, 25), 100: (5, 5, 4), 2000: (10, 10, 20)}


def lattice_dims(n):
    if n in DIMS:
        return DIMS[n]
    nx = max(1, round(n ** (1.0 / 3.0)))
    return nx, nx, int(math.ceil(n / (nx * nx)))


def make_system(n, variant="dense", skin=0.3, order="lattice"):
    """The scene as a System, its spheres stored in the lattice's row order (x fastest, z
    slowest), in a random order (``order="shuffle"``, seeded), or shuffled and then put back in
    cell order by :func:`demcli.state.order.cell_order` as a dynamic stage does (``"cells"``):
    what memory locality is worth, and what the stage's reordering recovers."""
    nx, ny, nz = lattice_dims(n)
    s = SPACING[variant]
    jit = (s - D) / 4.0
    rng = np.random.RandomState(12345)
    idx = np.arange(n)
    pos = np.empty((n, 3))
    pos[:, 0] = (idx % nx + 0.5) * s + rng.uniform(-jit, jit, n)
    pos[:, 1] = ((idx // nx) % ny + 0.5) * s + rng.uniform(-jit, jit, n)
    pos[:, 2] = (idx // (nx * ny) + 0.5) * s
    vel = rng.uniform(-0.1, 0.1, (n, 3))
    if order != "lattice":
        perm = np.random.RandomState(1).permutation(n)
        pos, vel = pos[perm], vel[perm]
    if order == "cells":
        perm = cell_order(pos, mean_spacing(pos))
        pos, vel = pos[perm], vel[perm]
    return system_of(pos, vel, (nx * s, ny * s, 2.0 * nz * s), skin)


def system_of(pos, vel, box, skin=0.3):
    """A System of the scene's spheres (d 2 mm, rho 2650, the linear law, gravity, dt 1e-6 s) at
    ``pos`` with ``vel`` in the closed box (0, 0, 0)..``box`` [m]."""
    n = len(pos)
    idx = np.arange(n)
    m = RHO * math.pi / 6 * D ** 3
    zeta = -math.log(0.5) / math.sqrt(math.pi ** 2 + math.log(0.5) ** 2)
    cn = 2 * zeta * math.sqrt(m / 2 * KN)
    groups = {
        "bodies": {"x": pos, "v": vel, "omega": np.zeros((n, 3)), "q": np.tile([1.0, 0, 0, 0], (n, 1)),
                   "mass": np.full(n, m), "inertia": np.full((n, 3), 0.1 * m * D * D), "flags": np.zeros(n, np.int8),
                   "id": idx.astype(np.int64)},
        "spheres": {"body": idx.astype(np.int64), "offset": np.zeros((n, 3)), "radius": np.full(n, D / 2),
                    "material": np.zeros(n, np.int64)}}
    walls = Walls.box_faces(tuple(box))
    model = ContactModel(law="linear", kn=KN, kt=KN / 4, cn=cn)
    mats = [Material("glass", RHO, friction=0.5)]
    plan = make_plan(["gravity", "friction"], walls=True)
    return System(groups, mats, model, plan, walls, Dynamics(gravity=(0, 0, -9.81), skin=skin), dt=1e-6)
