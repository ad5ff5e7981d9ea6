"""Stress, fabric and velocity statistics of bodies and their contacts (numpy; fixed summation
order: ``np.einsum`` without BLAS, contacts in the order given).

Sign convention: stresses are **compression positive** (a granular bed under its own weight has
sigma_zz > 0), as the other demcli records (docs/records.md).
"""

from typing import NamedTuple

import numpy as np


class Sides(NamedTuple):
    """One row per body side of each contact (a pair has two, a wall contact one: the wall's side
    is left out). body: (m,) int; branch: (m, 3) x_b - x_c, from the contact point to the body's
    centre [m]; force: (m, 3) the contact's force on the body [N]; normal: (m, 3) the contact's
    unit normal; contact: (m,) int its row in the ContactSet."""

    body: np.ndarray
    branch: np.ndarray
    force: np.ndarray
    normal: np.ndarray
    contact: np.ndarray


def sides(contacts, x):
    """The :class:`Sides` of a :class:`demcli.measure.contacts.ContactSet` with body centres
    ``x`` (n, 3) [m]: side a with F, then side b with -F for each pair, in contact order."""
    k = np.arange(len(contacts.a))
    pair = np.flatnonzero(contacts.b >= 0)
    body = np.concatenate([contacts.a, contacts.b[pair]])
    point = np.concatenate([contacts.point, contacts.point[pair]])
    force = np.concatenate([contacts.force, -contacts.force[pair]])
    return Sides(body, np.asarray(x, float)[body] - point, force,
                 np.concatenate([contacts.normal, contacts.normal[pair]]), np.concatenate([k, pair]))


def love_weber(branch, force, volume):
    """Love-Weber mean stress [Pa], (3, 3), compression positive:

        sigma_ij = (1 / V) sum_s (x_b - x_c)_i f_j

    over the body sides s (branch x_b - x_c [m], force f on the body [N]) of the contacts of the
    bodies in a region of volume V [m^3]. For a pair with both bodies inside the two sides add up
    to (x_a - x_b)_i F_j, the contact virial. At equilibrium the tensor is symmetric; contact
    moments (rolling resistance, parallel bonds) are not part of it. NaN for V = 0.
    """
    s = np.einsum("ki,kj->ij", np.asarray(branch, float).reshape(-1, 3), np.asarray(force, float).reshape(-1, 3))
    return s / volume if volume > 0.0 else np.full((3, 3), np.nan)


def invariants(sigma):
    """(p, q) [Pa] of a stress (3, 3), compression positive: the mean stress p = tr(sigma) / 3 and
    the deviator q = sqrt(3/2 s : s), s the deviatoric part of the symmetric part of sigma
    (triaxial test: q = sigma_1 - sigma_3)."""
    sym = 0.5 * (sigma + sigma.T)
    p = float(np.trace(sym)) / 3.0
    dev = sym - p * np.eye(3)
    return p, float(np.sqrt(1.5 * np.einsum("ij,ij->", dev, dev)))


def fabric(normals, weights=None):
    """Fabric tensor phi = sum_c w_c n_c (x) n_c / sum_c w_c (3, 3), trace 1: of the contact
    normals (w = 1, Satake 1982) or force-weighted (w = |F_n|). NaN without contacts (or weight)."""
    n = np.asarray(normals, float).reshape(-1, 3)
    w = np.ones(len(n)) if weights is None else np.asarray(weights, float)
    total = float(np.sum(w))
    if total <= 0.0:
        return np.full((3, 3), np.nan)
    return np.einsum("k,ki,kj->ij", w, n, n) / total


def anisotropy(phi):
    """Scalar fabric anisotropy a = sqrt(3/2 a_ij a_ij) with a_ij = 15/2 (phi_ij - delta_ij / 3), the
    deviatoric coefficients of the normals' density E(n) = (1 + a_ij n_i n_j) / (4 pi) (Rothenburg &
    Bathurst 1989); axisymmetric fabric: a = a_1 - a_3; 0 for isotropic normals."""
    a = 7.5 * (phi - np.trace(phi) / 3.0 * np.eye(3))
    return float(np.sqrt(1.5 * np.einsum("ij,ij->", a, a)))


def velocity_stats(mass, v):
    """(V (3,), v_rms) [m/s]: the mass-weighted mean velocity V = sum m v / sum m of the bodies and
    the rms of their fluctuations, sqrt(sum m |v - V|^2 / sum m). NaN for no bodies."""
    m = np.asarray(mass, float)
    total = float(np.sum(m))
    if total <= 0.0:
        return np.full(3, np.nan), float("nan")
    mean = np.einsum("k,ki->i", m, v) / total
    dv = v - mean
    return mean, float(np.sqrt(np.einsum("k,ki,ki->", m, dv, dv) / total))


def symmetric_columns(prefix, t):
    """{prefix_xx: t_xx, prefix_yy, prefix_zz, prefix_xy, prefix_xz, prefix_yz} of the symmetric
    part of a (3, 3) tensor."""
    sym = 0.5 * (t + t.T)
    return {f"{prefix}_{'xyz'[i]}{'xyz'[j]}": float(sym[i, j]) for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2),
                                                                            (1, 2))}
