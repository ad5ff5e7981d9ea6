"""Scenes built by hand for the measure tests: Systems (never stepped: no engine compiled) whose
stored contacts carry given forces."""

import numpy as np
import pytest

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls


def _system(x, r, pairs, pair_force, wall_rows, walls, sbody=None, soff=None, mass=None, bonds=None):
    """A System of spheres (or clumps: body centres ``x``, ``sbody``, ``soff``) whose stored
    contacts are ``pairs`` (k, 2) sphere indices with ``pair_force`` (k, 3) on the first, and
    ``wall_rows`` [(sphere, wall, force (3,))]; ``bonds``: the state groups ``bonds`` and
    ``bond_models``."""
    x, r = np.asarray(x, float).reshape(-1, 3), np.asarray(r, float)
    clumps = sbody is not None
    sbody = np.arange(len(r)) if sbody is None else np.asarray(sbody, np.int64)
    soff = np.zeros((len(r), 3)) if soff is None else np.asarray(soff, float)
    nb = len(x)
    m = np.bincount(sbody, weights=2500.0 * 4.0 / 3.0 * np.pi * r ** 3, minlength=nb) if mass is None else mass
    bodies = {"x": x, "v": np.zeros((nb, 3)), "omega": np.zeros((nb, 3)), "q": np.tile([1.0, 0, 0, 0], (nb, 1)),
              "mass": np.asarray(m, float), "inertia": np.ones((nb, 3)) * 1e-6, "id": np.arange(nb),
              "flags": np.zeros(nb, np.int8)}
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    contacts = {"i": pairs[:, 0], "j": pairs[:, 1], "force": np.asarray(pair_force, float).reshape(-1, 3)}
    wall_contacts = {"sphere": np.array([w[0] for w in wall_rows], np.int64),
                     "wall": np.array([w[1] for w in wall_rows], np.int64),
                     "force": np.array([w[2] for w in wall_rows], float).reshape(-1, 3)}
    groups = {"bodies": bodies, "spheres": {"body": sbody, "offset": soff, "radius": r,
                                            "material": np.zeros(len(r), np.int64)},
              "contacts": contacts, "wall_contacts": wall_contacts, **(bonds or {})}
    return System(groups, [Material("glass", 2500.0)], ContactModel(),
                  make_plan([], clumps=clumps, walls=len(walls) > 0, bonds=bonds is not None), walls, Dynamics(),
                  dt=1.0)


def lattice(n, d=1.0, pressure=1.0):
    """A simple cubic lattice of n^3 touching spheres (diameter d) filling the box [0, n d]^3 of six
    walls, under an isotropic pressure: every contact (spheres and walls) pushes with P d^2."""
    g = (np.arange(n) + 0.5) * d
    x = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    f = pressure * d * d
    pairs, forces = [], []
    for a in range(len(x)):
        for b in range(a + 1, len(x)):
            gap = x[b] - x[a]
            if abs(np.linalg.norm(gap) - d) < 1e-9 * d:
                pairs.append((a, b))
                forces.append(-f * gap / d)  # on a, away from b
    walls = Walls.box_faces((n * d,) * 3)
    rows = []
    for a in range(len(x)):
        for k in range(len(walls)):
            n_k = np.asarray(walls.normal[k], float)
            if abs((x[a] - walls.point[k]) @ n_k - 0.5 * d) < 1e-9 * d:
                rows.append((a, k, f * n_k))
    return _system(x, np.full(len(x), 0.5 * d), pairs, forces, rows, walls)


@pytest.fixture
def make_system():
    return _system


@pytest.fixture
def make_lattice():
    return lattice
