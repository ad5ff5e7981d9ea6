"""The contacts of a scene as arrays, for the measures: pairs, wall contacts and bonds.

Built on :func:`demcli.stages.contact_record.contact_rows` (sphere, clump and polyhedron scenes:
the contact point where the engine applies the force, the normal, the force on i), plus, in a
sphere scene with bonds, every intact bond and every broken bond still seated (the bonds the
engine counts as touching; a pair a bond holds is no contact of the contact list), with the
force the bond pass applied at the last step, at the point on the line of centres r_i - delta/2
from i. A clump's member contacts are contacts of its body (two member pairs of one clump pair
are two contacts).
"""

import math
from typing import NamedTuple

import numpy as np

from demcli.stages.contact_record import contact_rows


class ContactSet(NamedTuple):
    """k contacts. a: (k,) int body index of side i; b: (k,) int body index of side j, -1 for a
    wall; wall: (k,) int wall index, -1 for a pair; point: (k, 3) contact point [m]; force: (k, 3)
    force on a [N] (-force on b); normal: (k, 3) unit normal from b (the wall) to a; overlap: (k,)
    [m]; bond: (k,) int -1 for a contact, else the bond's state (0 intact, 1 broken in tension,
    2 broken in shear: seated)."""

    a: np.ndarray
    b: np.ndarray
    wall: np.ndarray
    point: np.ndarray
    force: np.ndarray
    normal: np.ndarray
    overlap: np.ndarray
    bond: np.ndarray

    def normal_force(self):
        """(k,) F . n [N], > 0 pushing apart."""
        return np.einsum("ij,ij->i", self.force, self.normal)

    def tangential_force(self):
        """(k,) |F - (F . n) n| [N]."""
        return np.linalg.norm(self.force - self.normal_force()[:, None] * self.normal, axis=1)


def empty():
    """A ContactSet without contacts."""
    z = np.zeros(0, np.int64)
    return ContactSet(z, z.copy(), z.copy(), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
                      z.copy())


def _from_rows(system, rows):
    if not rows:
        return empty()
    ids = np.asarray(system.body_id, np.int64)
    index = np.full(int(ids.max()) + 1, -1, np.int64)
    index[ids] = np.arange(len(ids))
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    a = index[col["i"].astype(np.int64)]
    j = col["j"].astype(np.int64)
    pair = j >= 0
    b = np.where(pair, index[np.where(pair, j, 0)], -1)
    wall = np.where(pair, -1, -j - 1)
    normal = np.stack([col["nx"], col["ny"], col["nz"]], axis=1)
    ft = np.stack([col["ftx"], col["fty"], col["ftz"]], axis=1)
    return ContactSet(a, b, wall, np.stack([col["cx"], col["cy"], col["cz"]], axis=1),
                      col["fn"][:, None] * normal + ft, normal, col["overlap"], np.full(len(a), -1, np.int64))


def _bonds(system):
    """The touching bonds of a sphere scene (intact, or broken and seated) as a ContactSet."""
    from demcli.kernels import bonds as B

    bd = system.bonds
    ba = getattr(system, "_bond_arrays", None)
    if not len(bd) or ba is None:
        return empty()
    keep = np.flatnonzero((bd.state == B.INTACT) | bd.seated())
    i, j = np.asarray(bd.i, np.int64)[keep], np.asarray(bd.j, np.int64)[keep]
    d = system.xs[i] - system.xs[j]
    dist = np.linalg.norm(d, axis=1)
    n = d / np.maximum(dist, math.ulp(1.0))[:, None]
    delta = system.rad[i] + system.rad[j] - dist
    point = system.xs[i] - (system.rad[i] - 0.5 * delta)[:, None] * n
    return ContactSet(system.sbody[i], system.sbody[j], np.full(len(i), -1, np.int64), point,
                      np.asarray(ba[7])[keep], n, delta, np.asarray(bd.state, np.int64)[keep])


def contact_set(system):
    """Every contact of the system now (pairs, wall contacts, then bonds) as a :class:`ContactSet`."""
    out = _from_rows(system, contact_rows(system))
    if system.plugin.name == "spheres":
        bonds = _bonds(system)
        if len(bonds.a):
            out = ContactSet(*(np.concatenate([x, y]) for x, y in zip(out, bonds)))
    return out
