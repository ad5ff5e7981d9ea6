"""contact.geometry_refresh (issue #30): a touching polyhedron pair evaluated exactly every k-th step
and linearized in between, V = V_0 - S_0 . (p_i - p_j) (demcli.kernels.shapes.polyhedra._linear_volume).

Checked here against the exact intersection (demcli.kernels.polyhedra.overlap): the linearized volume
is V's first-order expansion in the rigid motions of both bodies (its error falls 4 times when the
motion halves, and is below 1e-3 V_0 for a motion of 1e-3 of the stones' size); the loaded bed's
measured force error and settlement cost are in docs/polyhedra.md."""

import numba
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from demcli.geometry.generate import random_polyhedron
from demcli.geometry.polyhedron import convex_hull
from demcli.kernels.polyhedra import overlap_ws, place, polyhedron_overlap, scratch
from demcli.kernels.shapes.polyhedra import LINEAR_COLS, _linear_volume, _store_linear


@numba.njit
def _linearized(x0, q0, x1, q1, vol, g, s, fw):
    """V linearized at (x1, q1) about the exact evaluation (vol, g, s; moments in fw) at (x0, q0)."""
    pbox = np.zeros((1, LINEAR_COLS))
    _store_linear(pbox, 0, x0, q0, 0, 1, vol, g[0], g[1], g[2], s[0], s[1], s[2], fw, 4)
    return _linear_volume(pbox, 0, x1, q1, 0, 1)


def _exact_with_moments(pa, pb):
    """overlap_ws of two placed bodies: (V, g, S) and its scratch fw (the moments in fw[6:12])."""
    buf, fw, planes = scratch(max(np.diff(pa.face_start).max(), np.diff(pb.face_start).max()),
                              max(len(pa.normals), len(pb.normals)))
    r = overlap_ws(*pa.args(), *pb.args(), buf, fw, planes)
    return r[0], np.array(r[1:4]), np.array(r[4:7]), fw


def _centred(rng, axes):
    p = random_polyhedron(rng, 24, axes)
    return convex_hull(p.vertices - p.centroid)


def _quat(rotation):
    x, y, z, w = rotation.as_quat()
    return np.array([w, x, y, z])


def _moved(x, q, eps, t, axis):
    """Translation eps t and rotation eps |axis| about axis (the centroid fixed) applied to (x, q)."""
    x1 = x + eps * t
    r = Rotation.from_rotvec(eps * axis) * Rotation.from_quat([q[1], q[2], q[3], q[0]])
    return x1, _quat(r)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_linearized_volume_is_the_first_order_expansion(seed):
    # Given: two stones (ellipsoid hulls ~40 x 30 x 25 mm) overlapping by a few mm, and their exact V, g, S
    rng = np.random.default_rng(seed)
    a = _centred(rng, (0.02, 0.015, 0.012))
    b = _centred(rng, (0.02, 0.015, 0.012))
    qa = _quat(Rotation.random(random_state=seed))
    qb = _quat(Rotation.random(random_state=seed + 10))
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    q = np.array([qa, qb])
    pa, pb = place(a, x[0], q[0]), place(b, x[1], q[1])
    # B moved along a random direction until the overlap is 5 % of the smaller volume
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    lo, hi = 0.0, 0.1
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        v, _, _ = polyhedron_overlap(pa, place(b, mid * u, q[1]))
        lo, hi = (mid, hi) if v > 0.05 * min(a.volume, b.volume) else (lo, mid)
    x[1] = lo * u
    vol, g, s, fw = _exact_with_moments(pa, place(b, x[1], q[1]))
    assert vol > 0
    # When: both bodies make random small rigid motions (translation and turn about the centroid)
    motion = [(rng.normal(size=3), rng.normal(size=3) / 0.02) for _ in range(2)]
    errors = []
    for eps in (2e-5, 1e-5, 5e-6):
        x1 = x.copy()
        q1 = q.copy()
        for k in range(2):
            x1[k], q1[k] = _moved(x[k], q[k], eps, *motion[k])
        exact, _, _ = polyhedron_overlap(place(a, x1[0], q1[0]), place(b, x1[1], q1[1]))
        lin, _, _, _ = _linearized(x, q, x1, q1, vol, g, s, fw)
        change = abs(exact - vol)
        errors.append((abs(lin - exact), change))
    # Then: the volume changed by many times the linearization's error, and the error is second order
    for err, change in errors:
        assert err < 0.01 * change, errors
    assert errors[0][0] < 1e-3 * vol
    for (e1, _), (e2, _) in zip(errors, errors[1:]):
        assert 0.15 < e2 / e1 < 0.35, errors
