"""Sphere-polyhedron contact geometry (demcli.kernels.sphere_polyhedron) against closed forms on a
cube, a regular tetrahedron and an octahedron, against a constrained minimisation (SLSQP) and
surface sampling on random polyhedra, and in degenerate positions. Lengths in m; each test states
its tolerance."""

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from demcli.geometry import convex_hull, random_polyhedron
from demcli.kernels.polyhedra import place, to_world_planes, to_world_vertices
from demcli.kernels.sphere_polyhedron import DEGENERATE_REL, closest_feature, sphere_polyhedron_overlap
from demcli.state.polyhedra import ShapeTable

S3 = math.sqrt(3.0)
CUBE = convex_hull(np.array(list(itertools.product([-0.5, 0.5], repeat=3))))
TETRA = convex_hull(np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float))
OCTA = convex_hull(np.vstack([np.eye(3), -np.eye(3)]))
POSES = {"identity": (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])),
         "moved": (np.array([3.0, -2.0, 5.0]), np.array([0.9, 0.2, -0.3, 0.25]) / math.sqrt(1.0025))}


def body(poly, x, q):
    """The kernel's world arrays (v, fs, fv, off, n, d) of ``poly`` placed at (x, q)."""
    return place(poly, x, q).args()[:6]


def rotate(q, u):
    """R(q) u for q = (w, x, y, z), the convention of demcli.kernels.quat."""
    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).apply(u)


def feature(c, arrays):
    """closest_feature at the point c: (s, p (3,), n (3,))."""
    r = closest_feature(float(c[0]), float(c[1]), float(c[2]), *arrays)
    return r[0], np.array(r[1:4]), np.array(r[4:7])


def unit(u):
    u = np.asarray(u, float)
    return u / np.linalg.norm(u)


# ----------------------------------------------------------------------------- closed forms

# (shape, region, point c, s, n, p) in the body frame
CASES = [
    (CUBE, "face", [0.8, 0.1, -0.2], 0.3, [1, 0, 0], [0.5, 0.1, -0.2]),
    (CUBE, "edge", [0.8, 0.9, 0.1], 0.5, [0.6, 0.8, 0], [0.5, 0.5, 0.1]),
    (CUBE, "vertex", [0.7, 0.8, -1.1], 0.7, unit([0.2, 0.3, -0.6]), [0.5, 0.5, -0.5]),
    (TETRA, "face", np.array([-1, -1, -1]) / 3 - 0.2 * np.array([1, 1, 1]) / S3, 0.2, -np.ones(3) / S3,
     np.array([-1, -1, -1]) / 3),
    (TETRA, "edge", [1.25, -0.1 / math.sqrt(2), -0.1 / math.sqrt(2)], 0.25, [1, 0, 0],
     [1, -0.1 / math.sqrt(2), -0.1 / math.sqrt(2)]),
    (TETRA, "vertex", [1.3, 1.3, 1.3], 0.3 * S3, np.ones(3) / S3, [1, 1, 1]),
    (OCTA, "face", np.ones(3) / 3 + 0.2 * np.ones(3) / S3, 0.2, np.ones(3) / S3, np.ones(3) / 3),
    (OCTA, "edge", np.array([0.5, 0.5, 0]) + 0.3 * unit([1, 1, 0]), 0.3, unit([1, 1, 0]), [0.5, 0.5, 0]),
    (OCTA, "vertex", [1.4, 0.1, -0.05], math.sqrt(0.16 + 0.01 + 0.0025), unit([0.4, 0.1, -0.05]), [1, 0, 0]),
]
# inside: 0.05 below the mean of each face's vertices c (s = -0.05, n = n_f, p = c)
CASES += [(poly, f"inside face {f}", c - 0.05 * nf, -0.05, nf, c)
          for poly in (CUBE, TETRA, OCTA)
          for f, (nf, c) in enumerate(zip(poly.normals, [poly.vertices[i].mean(axis=0) for i in poly.faces]))]


@pytest.mark.parametrize("pose", POSES)
@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{len(c[0].vertices)}v-{c[1]}")
def test_closed_forms(case, pose):
    # Given a cube, a regular tetrahedron or an octahedron, placed as is or turned and moved far
    # from the origin, and a point in a face, edge or vertex region or inside near a face
    poly, _, c, s_ex, n_ex, p_ex = case
    x, q = POSES[pose]
    arrays = body(poly, x, q)
    # When its closest feature is found
    s, p, n = feature(x + rotate(q, c), arrays)
    # Then the distance, the surface point and the normal are the closed forms, to 1e-12 of
    # the coordinates (measured: 1.2e-15)
    tol = 1e-12 * (1 + np.abs(x).max())
    assert s == pytest.approx(s_ex, abs=tol)
    assert np.abs(p - (x + rotate(q, p_ex))).max() < tol
    assert np.abs(n - rotate(q, n_ex)).max() < tol


@pytest.mark.parametrize("pose", POSES)
@pytest.mark.parametrize("poly, inradius", [(CUBE, 0.5), (TETRA, 1 / S3), (OCTA, 1 / S3)])
def test_centre_takes_a_nearest_face(poly, inradius, pose):
    # Given the centre of a body whose faces are all equally far (a tie between faces)
    x, q = POSES[pose]
    arrays = body(poly, x, q)
    nrm, d = arrays[4], arrays[5]
    s, p, n = feature(x, arrays)
    # Then s = -inradius, n is one of the face normals and p = c - s n lies on that face
    # (1e-12 of the coordinates)
    tol = 1e-12 * (1 + np.abs(x).max())
    assert s == pytest.approx(-inradius, abs=tol)
    assert np.abs(nrm - n).max(axis=1).min() < tol
    assert np.abs(p - (x - s * n)).max() < tol
    assert abs((nrm @ p - d).max()) < tol


# ----------------------------------------------------------------------------- random polyhedra

def random_bodies():
    """Three random polyhedra (8, 20 and 40 vertices, elongated, far from the origin, turned)."""
    rng = np.random.default_rng(20240611)
    out = []
    for npts, axes in [(8, (1.0, 0.6, 0.4)), (20, (0.3, 0.5, 0.2)), (40, (2.0, 1.0, 1.5))]:
        poly = random_polyhedron(rng, npts, axes)
        out.append(place(poly, rng.uniform(-5, 5, 3), unit(rng.normal(size=4))))
    return out


BODIES = random_bodies()


def probe_points(a, rng, count):
    """Points uniform in the ball of 1.5 bounding radii, and as many about random surface points
    (near faces, edges and vertices), half of them within 2 % of the radius, half within 1e-6."""
    u = rng.normal(size=(count, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    ball = a.center + 1.5 * a.radius * u * np.cbrt(rng.uniform(size=(count, 1)))
    spread = np.where(np.arange(count) % 2 == 0, 0.02, 1e-6)[:, None] * a.radius
    near = surface_samples(a, rng, count) + spread * rng.normal(size=(count, 3))
    return np.vstack([ball, near])


def surface_samples(a, rng, count):
    """count points uniform on the faces of the placed body a (fan triangles, area-weighted)."""
    tris = [(f[0], f[i], f[i + 1]) for f in (a.face_vertices[a.face_start[k]:a.face_start[k + 1]]
                                            for k in range(len(a.face_start) - 1)) for i in range(1, len(f) - 1)]
    t = a.vertices[np.array(tris)]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    pick = rng.choice(len(t), size=count, p=area / area.sum())
    r1 = np.sqrt(rng.uniform(size=(count, 1)))
    r2 = rng.uniform(size=(count, 1))
    tp = t[pick]
    return (1 - r1) * tp[:, 0] + r1 * (1 - r2) * tp[:, 1] + r1 * r2 * tp[:, 2]


def slsqp_distance(a, c):
    """Reference: min |z| subject to n_f . (c + z) <= d_f (scipy SLSQP from the centroid), in
    coordinates about c scaled by L = max_f n_f . c - d_f (> 0 outside, a lower bound of the
    distance), which keeps far-placed bodies and tiny distances well conditioned."""
    h = a.offsets - a.normals @ c
    scale = -h.min()
    res = minimize(lambda y: float(y @ y), (a.center - c) / scale, jac=lambda y: 2 * y, method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda y: h / scale - a.normals @ y,
                                 "jac": lambda y: -a.normals}], options={"ftol": 1e-14, "maxiter": 200})
    assert res.success, res.message
    return math.sqrt(res.fun) * scale


@pytest.mark.parametrize("k", range(len(BODIES)))
def test_random_polyhedra_against_references(k):
    # Given a random polyhedron (8-40 vertices, elongated, turned, far from the origin) and 300
    # points around it: in a ball of 1.5 bounding radii and near its surface
    a = BODIES[k]
    rng = np.random.default_rng(k)
    arrays = a.args()[:6]
    pts = probe_points(a, rng, 150)
    size = a.radius
    tol = 1e-12 * (size + np.abs(a.center).max())
    samples = surface_samples(a, rng, 4000)
    regions = {1: 0, 2: 0, 3: 0}
    for c in pts:
        s, p, n = feature(c, arrays)
        dist = np.linalg.norm(c - p)
        # Then n is a unit vector, p lies on the surface (max_f n_f . p - d_f = 0) and
        # c = p + s n (each to 1e-12 of the coordinates; measured 2e-15)
        assert abs(np.linalg.norm(n) - 1) < 1e-12
        assert abs((a.normals @ p - a.offsets).max()) < tol
        assert np.abs(c - (p + s * n)).max() < tol
        # and no surface point is nearer than |s| (4000 samples)
        assert np.linalg.norm(samples - c, axis=1).min() >= abs(s) - tol
        if s > 0:
            # outside: p is the projection of c onto the body, (c - p) . (y - p) <= 0 for every
            # vertex y (the variational inequality of the nearest point of a convex set;
            # 1e-12 of size^2), and the SLSQP distance agrees to 1e-9 relative or 1e-12 of the
            # coordinates (measured: within 1e-14 of the coordinates, the round-off of its offsets h)
            assert dist == pytest.approx(s, abs=tol)
            assert ((a.vertices - p) @ (c - p)).max() < 1e-12 * size * (size + np.abs(a.center).max())
            assert s == pytest.approx(slsqp_distance(a, c), rel=1e-9, abs=tol)
            regions[min(3, int(np.sum(np.abs(a.normals @ p - a.offsets) < 1e-9 * size)))] += 1
        else:
            # inside: s is minus the distance to the nearest face plane
            assert s == pytest.approx((a.normals @ c - a.offsets).max(), abs=tol)
    # and the points covered the face, edge and vertex regions (at least 10 each)
    assert min(regions.values()) >= 10, regions


def test_normal_is_the_gradient_of_the_distance():
    # Given points outside a random polyhedron, at least 5 % of its radius away
    a = BODIES[2]
    rng = np.random.default_rng(10)
    arrays = a.args()[:6]
    h = 1e-6 * a.radius
    checked = 0
    for c in probe_points(a, rng, 100):
        s, _, n = feature(c, arrays)
        if s < 0.05 * a.radius:
            continue
        # Then central differences of s along the axes give n (error h / s + round-off / h,
        # 1e-6 allowed; measured 2e-10)
        grad = [(feature(c + h * e, arrays)[0] - feature(c - h * e, arrays)[0]) / (2 * h) for e in np.eye(3)]
        assert np.abs(np.array(grad) - n).max() < 1e-6
        checked += 1
    assert checked >= 50


def test_rows_of_a_shape_table():
    # Given two templates in one polyhedron_shapes table, and body 1 (the octahedron's rows:
    # face offsets that do not start at 0, vertex rows offset by the first template's), placed
    # as in demcli.kernels.shapes.polyhedra (world rows bvstart / bfstart, planes by to_world_planes)
    t = ShapeTable.from_polyhedra([random_polyhedron(np.random.default_rng(3), 30), OCTA])
    k = 1
    x = np.array([1.0, 2.0, -3.0])
    q = unit([0.3, -0.5, 0.7, 0.2])
    v0, v1, f0, f1 = t.vertex_start[k], t.vertex_start[k + 1], t.face_start[k], t.face_start[k + 1]
    wvert = np.empty((v1 - v0, 3))
    to_world_vertices(t.vertices[v0:v1], x, q, wvert)
    wnorm = np.empty((f1 - f0, 3))
    woff = np.empty(f1 - f0)
    to_world_planes(t.face_normal[f0:f1], t.face_offset[f0:f1], x, q, wnorm, woff)
    fs = t.face_vertex_start[f0:f1 + 1]
    rows = (wvert, fs, t.face_vertices, int(v0), wnorm, woff)
    # and the same body with its own rows counted from 0
    own = (wvert, fs - fs[0], t.face_vertices[fs[0]:fs[-1]] - v0, 0, wnorm, woff)
    rng = np.random.default_rng(4)
    for c in x + rng.uniform(-1.5, 1.5, size=(200, 3)):
        s, p, n = feature(c, rows)
        # Then both give the same result, bit for bit; p lies on the surface, and the distance is
        # the octahedron's: outside, (c - p) . (y - p) <= 0 over its 6 vertices y; inside, minus the
        # distance to the nearest template plane at x_b = R^T (c - x) (each 1e-12)
        assert (s, *p, *n) == closest_feature(*c, *own)
        assert abs((wnorm @ p - woff).max()) < 1e-12
        if s > 0:
            assert ((wvert - p) @ (c - p)).max() < 1e-12
        else:
            xb = rotate(np.r_[q[0], -q[1:]], c - x)
            assert s == pytest.approx((t.face_normal[f0:f1] @ xb - t.face_offset[f0:f1]).max(), abs=1e-12)


# ----------------------------------------------------------------------------- degenerate points

UP = math.nextafter(0.5, 1.0)  # one ulp outside the cube's faces


@pytest.mark.parametrize("c, faces", [
    ([0.5, 0.5, 0.1], [0, 1]), ([0.5, -0.5, 0.5], [0, 1, 2]), ([0.5, 0.0, 0.0], [0]),
    ([UP, UP, 0.1], [0, 1]), ([UP, -UP, UP], [0, 1, 2]), ([UP, 0.2, -0.3], [0])],
    ids=["on-edge", "on-vertex", "on-face", "ulp-off-edge", "ulp-off-vertex", "ulp-off-face"])
def test_points_on_the_surface(c, faces):
    # Given the unit cube and a point exactly on an edge, a vertex or a face, or one ulp outside
    a = place(CUBE)
    s, p, n = feature(np.array(c), a.args()[:6])
    # Then nothing is NaN, |s| is round-off (<= 1e-15), p is c (1e-15) and n is the normal of
    # one of the faces through the feature (1e-15), not a direction of a vanishing difference
    signs = np.sign(c)
    cone = [signs[i] * np.eye(3)[i] for i in faces]
    assert np.all(np.isfinite([s, *p, *n]))
    assert abs(s) <= 1e-15
    assert np.abs(p - c).max() <= 1e-15
    assert min(np.abs(n - m).max() for m in cone) <= 1e-15
    assert np.linalg.norm(c - p) <= DEGENERATE_REL * 0.5


def test_normal_turns_continuously_round_an_edge():
    # Given points at a distance 1e-3 from the cube's edge x = y = 0.5, at angles 0..90 deg
    # about it (from the +x face's normal to the +y face's)
    a = place(CUBE)
    for ang in np.linspace(0.0, math.pi / 2, 19):
        u = np.array([math.cos(ang), math.sin(ang), 0.0])
        s, p, n = feature(np.array([0.5, 0.5, 0.2]) + 1e-3 * u, a.args()[:6])
        # Then s = 1e-3, p is the edge point and n = u (1e-12)
        assert s == pytest.approx(1e-3, abs=1e-12)
        assert np.abs(p - [0.5, 0.5, 0.2]).max() < 1e-12
        assert np.abs(n - u).max() < 1e-12


# ----------------------------------------------------------------------------- sphere contact

@pytest.mark.parametrize("radius, delta", [(0.5, 0.2), (0.2, -0.1), (0.3, 0.0)])
def test_sphere_on_a_cube_face(radius, delta):
    # Given a sphere of radius R centred 0.3 in front of the face x = 0.5 of the unit cube
    x, q = POSES["moved"]
    arrays = body(CUBE, x, q)
    c = x + rotate(q, [0.8, 0.1, -0.2])
    r = sphere_polyhedron_overlap(*c, radius, *arrays)
    # Then delta = R - 0.3, n = +x (towards the sphere) and the contact point is the middle of
    # the overlap, x = 0.5 + 0.3 - (R - delta / 2) (to 1e-12 of the coordinates)
    tol = 1e-12 * (1 + np.abs(x).max())
    assert r[0] == pytest.approx(delta, abs=tol)
    assert np.abs(np.array(r[1:4]) - rotate(q, [1, 0, 0])).max() < tol
    assert np.abs(np.array(r[4:7]) - (x + rotate(q, [0.8 - radius + delta / 2, 0.1, -0.2]))).max() < tol


def test_sphere_overlap_is_the_closest_feature():
    # Given random points near a random polyhedron and spheres of random radii there
    a = BODIES[1]
    rng = np.random.default_rng(11)
    arrays = a.args()[:6]
    for c in probe_points(a, rng, 50):
        radius = rng.uniform(0.01, 0.5) * a.radius
        delta, nx, ny, nz, *xc = sphere_polyhedron_overlap(*c, radius, *arrays)
        s, p, n = feature(c, arrays)
        # Then delta = R - s, the normal is closest_feature's and the contact point lies halfway
        # between p and the sphere's deepest point c - R n (exactly, and to 1e-12 of the coordinates)
        assert delta == radius - s
        assert (nx, ny, nz) == tuple(n)
        assert np.abs(np.array(xc) - 0.5 * (p + c - radius * n)).max() < 1e-12 * (1 + np.abs(c).max())
