"""Narrow phase between convex polyhedra (demcli.kernels.polyhedra) against exact values,
Monte Carlo and finite differences, plus continuity and degenerate configurations."""

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from demcli.geometry import convex_hull, random_polyhedron
from demcli.kernels.polyhedra import (BOX_PAD, contact_frame, overlap, overlap_in_box, overlap_ws, place,
                                     polyhedron_overlap, polyhedron_plane_overlap, scratch)

CUBE = convex_hull(np.array(list(itertools.product([-0.5, 0.5], repeat=3))))


def box(lx, ly, lz):
    return convex_hull(np.array(list(itertools.product([-lx / 2, lx / 2], [-ly / 2, ly / 2], [-lz / 2, lz / 2]))))


def quat(axis, deg):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    a = math.radians(deg) / 2
    return np.concatenate([[math.cos(a)], math.sin(a) * axis])


def rotmat(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def contact(pa, xa, qa, pb, xb, qb):
    """(V, centroid, S, unit normal, area, depth) of pa placed at (xa, qa) and pb at (xb, qb)."""
    a, b = place(pa, xa, qa), place(pb, xb, qb)
    v, g, s = polyhedron_overlap(a, b)
    n = contact_frame(v, *s, *a.center, *b.center, a.radius, b.radius)
    return v, g, s, np.array(n[:3]), n[3], n[4]


def rel(a, b):
    return np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))) / max(1e-300, np.max(np.abs(b)))


# ----------------------------------------------------------------------------- exact values

OFFSETS = [(0.5, 0, 0), (0.3, 0.25, 0), (-0.3, 0.25, 0), (0.3, -0.2, 0.1), (-0.7, -0.4, 0.45), (0.9, 0.9, 0.9),
           (0, 0, 0), (1e-3, 0, -1e-3)]


@pytest.mark.parametrize("offset", OFFSETS)
@pytest.mark.parametrize("rotated", [False, True])
def test_offset_unit_cubes_exact(offset, rotated):
    # Given two unit cubes, B offset from A by o (overlap in 1, 2 or 3 axes; o = 0 coincident),
    # both optionally turned by the same rotation and moved far from the origin
    o = np.array(offset, float)
    q = quat([1, 2, 3], 37) if rotated else np.array([1.0, 0, 0, 0])
    shift = np.array([3.0, -2.0, 5.0]) if rotated else np.zeros(3)
    r = rotmat(q)
    v, g, s, n, area, depth = contact(CUBE, shift, q, CUBE, shift + r @ o, q)
    # Then V is the product of the overlaps per axis, the centroid the box centre, and
    # S = -(sign o_i x the face area across axis i); faces flush on an axis (o_i = 0) count once
    w = 1.0 - np.abs(o)
    s_exact = -np.sign(o) * np.array([w[1] * w[2], w[0] * w[2], w[0] * w[1]])
    assert v == pytest.approx(np.prod(w), rel=1e-12, abs=0)
    assert rel(g, shift + r @ (o / 2)) < 1e-12 * (1 + np.abs(shift).max())
    if np.any(o != 0):
        assert rel(s, r @ s_exact) < 1e-12
        assert area == pytest.approx(np.linalg.norm(s_exact), rel=1e-12, abs=0)
        assert rel(n, r @ s_exact / np.linalg.norm(s_exact)) < 1e-12
        assert depth == pytest.approx(np.prod(w) / np.linalg.norm(s_exact), rel=1e-12, abs=0)
    else:  # coincident: S vanishes to round-off
        assert np.abs(s).max() < 1e-12


def test_offset_cubes_symmetric_roles():
    # Given offset cubes, When A and B swap, Then V and g stay and S flips
    o = np.array([0.3, -0.2, 0.1])
    v1, g1, s1, *_ = contact(CUBE, np.zeros(3), quat([0, 0, 1], 0), CUBE, o, quat([0, 0, 1], 0))
    v2, g2, s2, *_ = contact(CUBE, o, quat([0, 0, 1], 0), CUBE, np.zeros(3), quat([0, 0, 1], 0))
    assert v1 == pytest.approx(v2, rel=1e-14, abs=0)
    assert rel(g1, g2) < 1e-14
    assert rel(s1, -s2) < 1e-14


@pytest.mark.parametrize("delta", [0.3, 0.05, 1e-3, 1e-6])
@pytest.mark.parametrize("height", [1.0, 2.0])
def test_cube_rotated_45_edge_into_face(delta, height):
    # Given A the unit cube and B a box of the same square section turned 45 deg about z,
    # its vertical edge pushed a depth delta into A's face x = 0.5 (height 1: top and bottom
    # faces coplanar with A's; height 2: B sticks out)
    h = math.sqrt(0.5)
    xb = 0.5 + h - delta
    v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], box(1, 1, height), [xb, 0, 0],
                                      quat([0, 0, 1], 45))
    # Then the overlap is a triangular prism: V = delta^2, centroid x = 0.5 - delta/3,
    # S = -2 delta x (two strips of B's faces, width delta sqrt 2, normals (-1, +-1, 0)/sqrt 2)
    # (V and depth to 1e-12 relative; centroid, S and n to 1e-12 of the body size or
    # relative, except for delta = 1e-6, where the round-off of B's turned vertices, ~1e-16,
    # against the prism's width 1e-6 gives 1e-10 relative (V, depth), 2e-11 (centroid),
    # 1e-15 (S, absolute) and 1e-10 (n))
    tiny = delta < 1e-3
    assert v == pytest.approx(delta ** 2, rel=1e-9 if tiny else 1e-12, abs=0)
    assert np.abs(g - [0.5 - delta / 3, 0, 0]).max() < (2e-11 if tiny else 1e-12)
    assert np.abs(s - [-2 * delta, 0, 0]).max() < (1e-15 if tiny else 1e-12 * 2 * delta)
    assert rel(n, [-1, 0, 0]) < (1e-10 if tiny else 1e-12)
    assert depth == pytest.approx(delta / 2, rel=1e-9 if tiny else 1e-12, abs=0)


def test_vertex_into_face_closed_form():
    # Given a cube standing on a corner (its diagonal along z) with the corner a depth
    # delta below A's top face z = 0.5
    q = quat([1, -1, 0], math.degrees(math.acos(1 / math.sqrt(3))))  # (1, 1, 1) -> z
    r = rotmat(q)
    corner = np.array(list(itertools.product([-0.5, 0.5], repeat=3))) @ r.T
    low = corner[np.argmin(corner[:, 2])]
    delta = 0.01
    xb = np.array([0, 0, 0.5 - delta]) - low
    v, g, s, n, *_ = contact(CUBE, np.zeros(3), [1, 0, 0, 0], CUBE, xb, q)
    # Then the overlap is the corner tetrahedron of the cube cut at height delta: three
    # perpendicular edges of length delta sqrt 3, volume (delta sqrt 3)^3 / 6, centroid at
    # 3/4 of the way from the corner to the cut, S = cut area x (+z)
    edge = delta * math.sqrt(3)
    assert v == pytest.approx(edge ** 3 / 6, rel=1e-10, abs=0)
    assert rel(g, [xb[0] + low[0], xb[1] + low[1], 0.5 - delta / 4]) < 1e-10
    assert rel(s, [0, 0, -math.sqrt(3) / 4 * (edge * math.sqrt(2)) ** 2]) < 1e-10  # equilateral cut


# ----------------------------------------------------------------------------- random pairs


def random_pair(rng, rel_depth):
    pa = random_polyhedron(rng, int(rng.integers(10, 21)), (1.0, rng.uniform(0.5, 1), rng.uniform(0.4, 1)))
    pb = random_polyhedron(rng, int(rng.integers(10, 21)), (1.0, rng.uniform(0.5, 1), rng.uniform(0.4, 1)))
    qa, qb = rng.normal(size=4), rng.normal(size=4)
    qa /= np.linalg.norm(qa)
    qb /= np.linalg.norm(qb)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    # B's centroid at distance t along u, t from a root search on V(t) = rel_depth V_min
    a = place(pa, -rotmat(qa) @ pa.centroid, qa)
    target = rel_depth * min(pa.volume, pb.volume)

    def placed_b(t):
        return place(pb, t * u - rotmat(qb) @ pb.centroid, qb)

    lo, hi = 0.0, 4.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if polyhedron_overlap(a, placed_b(mid))[0] > target else (lo, mid)
    return pa, pb, a, placed_b(lo), qa, qb


def inside(p, x):
    return np.all(x @ p.normals.T - p.offsets <= 0.0, axis=1)


@pytest.mark.parametrize("seed", range(6))
def test_random_pairs_against_monte_carlo(seed):
    # Given random convex polyhedra pairs with overlaps of 2-30 % of the smaller volume
    rng = np.random.default_rng(100 + seed)
    _, _, a, b, _, _ = random_pair(rng, rng.uniform(0.02, 0.3))
    v, g, s = polyhedron_overlap(a, b)
    # When 400 000 points are drawn uniformly in the overlap of the two bounding boxes
    lo = np.maximum(a.vertices.min(0), b.vertices.min(0))
    hi = np.minimum(a.vertices.max(0), b.vertices.max(0))
    n = 400_000
    x = lo + (hi - lo) * rng.random((n, 3))
    hit = inside(a, x) & inside(b, x)
    k = hit.sum()
    p = k / n
    box_v = np.prod(hi - lo)
    v_mc = p * box_v
    sigma_v = box_v * math.sqrt(p * (1 - p) / n)
    # Then V agrees within 4 sigma and the centroid within 4 standard errors per axis
    assert abs(v - v_mc) < 4 * sigma_v, (v, v_mc, sigma_v)
    pts = x[hit]
    g_mc = pts.mean(0)
    se = pts.std(0) / math.sqrt(k)
    assert np.all(np.abs(g - g_mc) < 4 * se + 1e-12), (g, g_mc, se)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("rel_depth", [1e-3, 0.05])
def test_random_pairs_s_is_minus_volume_gradient(seed, rel_depth):
    # Given a random pair, When A is moved by +-h along each axis
    rng = np.random.default_rng(200 + seed)
    pa, pb, a, b, qa, qb = random_pair(rng, rel_depth)
    v, g, s = polyhedron_overlap(a, b)
    h = 1e-6
    grad = np.empty(3)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        xa = -rotmat(qa) @ pa.centroid
        vp = polyhedron_overlap(place(pa, xa + e, qa), b)[0]
        vm = polyhedron_overlap(place(pa, xa - e, qa), b)[0]
        grad[k] = (vp - vm) / (2 * h)
    # Then S = -dV/dx_A to 1e-5 relative
    assert np.linalg.norm(s + grad) < 1e-5 * np.linalg.norm(s), (s, -grad)
    # And moving B instead gives +S
    xb = b.center - rotmat(qb) @ pb.centroid
    vp = polyhedron_overlap(a, place(pb, xb + [h, 0, 0], qb))[0]
    vm = polyhedron_overlap(a, place(pb, xb - [h, 0, 0], qb))[0]
    assert (vp - vm) / (2 * h) == pytest.approx(s[0], rel=1e-5, abs=1e-5 * np.linalg.norm(s))


def test_engine_layout_slices_give_the_same_result():
    # Given two bodies stored as the engine stores them (one vertex array, global face rows)
    rng = np.random.default_rng(7)
    _, _, a, b, _, _ = random_pair(rng, 0.01)
    ref = overlap(*a.args(), *b.args())
    verts = np.concatenate([a.vertices, b.vertices])
    nva = len(a.vertices)
    fvs = np.concatenate([a.face_start[:-1], b.face_start + len(a.face_vertices)]).astype(np.int64)
    fv = np.concatenate([a.face_vertices, b.face_vertices + nva]).astype(np.int64)
    nfa = len(a.normals)
    normals = np.concatenate([a.normals, b.normals])
    offsets = np.concatenate([a.offsets, b.offsets])
    # When B's arrays are slices with a vertex-row offset
    got = overlap(verts[:nva], fvs[:nfa + 1], fv, 0, normals[:nfa], offsets[:nfa], *a.center, a.radius,
                  verts[nva:], fvs[nfa:], fv, nva, normals[nfa:], offsets[nfa:], *b.center, b.radius)
    # Then nothing changes
    assert got == ref


def test_shared_scratch_gives_the_same_result_as_fresh_scratch():
    # Given random pairs of different sizes and one scratch sized for the largest of them, as
    # the engine's pair pass allocates it once per row and reuses it for every pair in the row
    rng = np.random.default_rng(11)
    pairs = [random_pair(rng, d)[2:4] for d in (0.001, 0.05, 0.2, 0.4)]
    most_faces = max(len(p.normals) for pair in pairs for p in pair)
    widest_face = max(int(np.diff(p.face_start).max()) for pair in pairs for p in pair)
    buf, fw, planes = scratch(widest_face, most_faces)
    for a, b in pairs:
        # When the overlap runs in the shared scratch, left dirty by the pair before
        got = overlap_ws(*a.args(), *b.args(), buf, fw, planes)
        # Then it is bit-identical to a call with scratch of its own size
        assert got == overlap(*a.args(), *b.args())
        assert got[0] > 0.0


# ----------------------------------------------------------------------------- coherent culling


def full_with_box(a, b):
    """overlap_ws of the pair and the bounding box of its intersection's pieces (fw[22:28])."""
    buf, fw, planes = scratch(int(max(np.diff(a.face_start).max(), np.diff(b.face_start).max())),
                              max(len(a.normals), len(b.normals)))
    r = overlap_ws(*a.args(), *b.args(), buf, fw, planes)
    return r, fw[22:28].copy(), (buf, fw, planes)


def moved(p, placed, q, rng, dist, angle):
    """p, placed with rotation q, moved by ``dist`` along a random direction and turned by
    ``angle`` rad about a random axis through its centre."""
    d = rng.normal(size=3)
    q2 = qmul(quat(rng.normal(size=3), math.degrees(angle)), q)
    c = placed.center + dist * d / np.linalg.norm(d)
    return place(p, c - rotmat(q2) @ p.centroid, q2)


def assert_same_contact(got, ref, size):
    v, g, s = got[0], np.array(got[1:4]), np.array(got[4:7])
    assert v == pytest.approx(ref[0], rel=1e-12, abs=0)
    assert np.abs(g - np.array(ref[1:4])).max() < 1e-12 * size
    assert np.abs(s - np.array(ref[4:7])).max() < 1e-12 * np.linalg.norm(ref[4:7])


@pytest.mark.parametrize("seed", range(8))
def test_overlap_in_box_after_a_small_move_matches_the_full_overlap(seed):
    # Given a random pair overlapping by 1e-4 .. 0.1 of the smaller volume and the bounding box
    # of its intersection, as the pair pass keeps it per touching pair
    rng = np.random.default_rng(500 + seed)
    pa, pb, a, b, qa, qb = random_pair(rng, 10.0 ** rng.uniform(-4, -1))
    _, pbox, ws = full_with_box(a, b)
    # When B moves by 1e-4 of its size and turns by 1e-4 rad (a few DEM steps) and the pair is
    # evaluated in that box widened by BOX_PAD of the smaller bounding radius
    b2 = moved(pb, b, qb, rng, 1e-4, 1e-4)
    pad = BOX_PAD * min(a.radius, b2.radius)
    got = overlap_in_box(*a.args(), *b2.args(), pbox + np.r_[-pad, -pad, -pad, pad, pad, pad], *ws)
    # Then the box holds the new intersection and the result is the full overlap's to 1e-12
    # (relative; round-off: the same pieces, clipped by fewer planes)
    ref = overlap(*a.args(), *b2.args())
    assert got[0] and ref[0] > 0.0
    assert_same_contact(got[1:], ref, 2 * max(a.radius, b2.radius))


@pytest.mark.parametrize("seed", range(4))
def test_overlap_in_box_never_returns_a_wrong_result(seed):
    # Given random pairs and culling boxes drawn around their intersection: shrunk, shifted,
    # grown, far away, flat
    rng = np.random.default_rng(600 + seed)
    accepted = refused = 0
    for _ in range(12):
        pa, pb, a, b, qa, qb = random_pair(rng, 10.0 ** rng.uniform(-4, -1))
        ref, pbox, ws = full_with_box(a, b)
        lo, hi = pbox[:3], pbox[3:]
        size = hi - lo
        for _ in range(20):
            c = 0.5 * (lo + hi) + rng.uniform(-0.6, 0.6, 3) * size * rng.choice([0.0, 0.3, 10.0])
            half = 0.5 * size * rng.uniform(0.5, 2.5, 3)
            # When the pair is evaluated in such a box
            got = overlap_in_box(*a.args(), *b.args(), np.r_[c - half, c + half], *ws)
            # Then it either refuses (the intersection may reach out of the box) or gives the
            # full overlap's result to 1e-12
            if got[0]:
                accepted += 1
                assert_same_contact(got[1:], ref, 2 * max(a.radius, b.radius))
                assert np.all(c - half < lo) and np.all(c + half > hi)
            else:
                refused += 1
    # and both outcomes occur (the draws test something)
    assert accepted > 20 and refused > 20


def test_overlap_in_box_refuses_an_empty_box_and_separated_bodies():
    # Given two unit cubes overlapping by 0.1 along x
    a, b = place(CUBE, (0.0, 0.0, 0.0)), place(CUBE, (0.9, 0.0, 0.0))
    ref, pbox, ws = full_with_box(a, b)
    assert ref[0] == pytest.approx(0.1, rel=1e-12)
    np.testing.assert_allclose(pbox, [0.4, -0.5, -0.5, 0.5, 0.5, 0.5], atol=1e-12)
    # When the box lies beside the intersection, or the bodies have parted since the box was
    # taken, then the evaluation is refused (the caller falls back to the full overlap)
    assert not overlap_in_box(*a.args(), *b.args(), np.r_[2.0, 2.0, 2.0, 3.0, 3.0, 3.0], *ws)[0]
    apart = place(CUBE, (1.2, 0.0, 0.0))
    assert not overlap_in_box(*a.args(), *apart.args(), pbox + np.r_[-0.01, -0.01, -0.01, 0.01, 0.01, 0.01],
                              *ws)[0]
    # and a box around it gives the exact overlap
    got = overlap_in_box(*a.args(), *b.args(), pbox + np.r_[-0.01, -0.01, -0.01, 0.01, 0.01, 0.01], *ws)
    assert got[0] and got[1] == pytest.approx(0.1, rel=1e-12)


# ----------------------------------------------------------------------------- walls


def clip_polygon_2d(poly, a, c):
    """Convex polygon (k, 2) cut to a . p <= c (an independent reference)."""
    out = []
    for i in range(len(poly)):
        p, q = poly[i - 1], poly[i]
        sp, sq = a @ p - c, a @ q - c
        if sq <= 0:
            if sp > 0:
                out.append(p + sp / (sp - sq) * (q - p))
            out.append(q)
        elif sp <= 0:
            out.append(p + sp / (sp - sq) * (q - p))
    return np.array(out)


def shoelace(p):
    """Area and centroid of a polygon (k, 2), about its first vertex (no cancellation)."""
    p0 = p[0]
    p = p - p0
    x, y = p[:, 0], p[:, 1]
    a = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    cx = np.sum((x + np.roll(x, -1)) * (x * np.roll(y, -1) - np.roll(x, -1) * y)) / (6 * a)
    cy = np.sum((y + np.roll(y, -1)) * (x * np.roll(y, -1) - np.roll(x, -1) * y)) / (6 * a)
    return a, p0 + np.array([cx, cy])


@pytest.mark.parametrize("tilt", [0.0, 10.0, 30.0, 45.0, 71.0])
@pytest.mark.parametrize("depth", [1e-9, 0.01, 0.3, 0.7, 1.2])
def test_cube_against_plane_exact(tilt, depth):
    # Given the unit cube turned by `tilt` about x, its lowest point `depth` below the wall z <= 0
    q = quat([1, 0, 0], tilt)
    r = rotmat(q)
    zmin = (np.array(list(itertools.product([-0.5, 0.5], repeat=3))) @ r.T)[:, 2].min()
    x = np.array([0.0, 0.0, -depth - zmin])
    a = place(CUBE, x, q)
    v, g, s = polyhedron_plane_overlap(a, [0, 0, 1], 0.0)
    # Then V, centroid and S = (cross-section area) z follow from the turned square (y, z)
    # cut by z <= 0 (extruded over x in [-0.5, 0.5])
    sq = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]) @ r[1:, 1:].T + x[1:]
    cut = clip_polygon_2d(sq, np.array([0.0, 1.0]), 0.0)
    area, c2 = shoelace(cut)
    on_wall = cut[np.abs(cut[:, 1]) < 1e-12]
    width = np.ptp(on_wall[:, 0]) if len(on_wall) else 0.0
    # (V to 1e-12 relative, plus 1e-15 / depth: the turned vertices carry a round-off of
    # ~1e-16, so a wedge 1e-9 deep is only defined to 1e-7 relative; the centroid to 1e-12
    # and S to 1e-13 of the body size)
    assert v == pytest.approx(area, rel=1e-12 + 1e-15 / depth, abs=0)
    assert np.abs(g - [0.0, c2[0], c2[1]]).max() < 1e-12
    assert np.abs(s - [0, 0, width]).max() < 1e-13


def test_plane_against_big_box_and_general_tilt():
    # Given a random polyhedron in a general orientation against a tilted wall
    rng = np.random.default_rng(3)
    p = random_polyhedron(rng, 16, (1.0, 0.7, 0.5))
    q = quat([0.3, -1, 0.4], 63)
    a = place(p, [0.2, 0.1, -0.05], q)
    nrm = np.array([0.2, -0.3, 1.0])
    nrm /= np.linalg.norm(nrm)
    v, g, s = polyhedron_plane_overlap(a, nrm, 0.05)
    # When the wall is replaced by a huge box whose top face is the wall plane
    big = box(100, 100, 100)
    zq = np.cross([0, 0, 1.0], nrm)
    ang = math.degrees(math.asin(np.linalg.norm(zq)))
    qw = quat(zq, ang)
    assert np.allclose(rotmat(qw) @ [0, 0, 1], nrm)
    w = place(big, nrm * (0.05 - 50.0), qw)
    v2, g2, s2 = polyhedron_overlap(a, w)
    # Then both routes agree (S of the wall: cross-section area x the wall normal)
    assert v == pytest.approx(v2, rel=1e-12, abs=0)
    assert rel(g, g2) < 1e-11
    assert rel(s, s2) < 1e-11
    assert rel(s / np.linalg.norm(s), nrm) < 1e-12


def test_plane_gradient_and_limits():
    # Given a polyhedron against a wall, Then S = -dV/dx, and V is 0 above / the volume below
    rng = np.random.default_rng(5)
    p = random_polyhedron(rng, 14, (1.0, 0.8, 0.6))
    q = quat([1, 1, 0], 20)
    nrm = np.array([0.0, 0.6, 0.8])
    h = 1e-6
    v, g, s = polyhedron_plane_overlap(place(p, [0, 0, 0.1], q), nrm, -0.2)
    vp = polyhedron_plane_overlap(place(p, [0, 0, 0.1 + h], q), nrm, -0.2)[0]
    vm = polyhedron_plane_overlap(place(p, [0, 0, 0.1 - h], q), nrm, -0.2)[0]
    assert -(vp - vm) / (2 * h) == pytest.approx(s[2], rel=1e-6, abs=0)
    assert polyhedron_plane_overlap(place(p, [0, 0, 10], q), nrm, -0.2)[0] == 0.0
    a = place(p, [0, 0, -10], q)
    v_all, g_all, s_all = polyhedron_plane_overlap(a, nrm, -0.2)
    assert v_all == pytest.approx(p.volume, rel=1e-12, abs=0)
    assert np.abs(s_all).max() < 1e-12
    # And buried in the wall, contact_frame falls back on the wall normal (B's "centre"
    # taken on the wall's side of A)
    n = contact_frame(v_all, *s_all, *a.center, *(a.center - nrm), a.radius, a.radius)
    assert rel(n[:3], nrm) < 1e-12


# ----------------------------------------------------------------------------- continuity, degenerate


def sweep(pa, qa, pb, qb, path):
    """(V, S, g) along a path of B positions, asserting finiteness."""
    a = place(pa, np.zeros(3), qa)
    out = []
    for xb in path:
        v, g, s = polyhedron_overlap(a, place(pb, xb, qb))
        assert np.isfinite(v) and np.all(np.isfinite(g)) and np.all(np.isfinite(s))
        out.append((v, *s))
    return np.array(out)


def assert_lipschitz(values, step, bound):
    jumps = np.abs(np.diff(values, axis=0)).max(axis=0) / step
    assert np.all(jumps <= bound), jumps


def test_face_to_face_slide_is_continuous():
    # Given B resting 0.01 deep on A's top face, slid along x across A's edges (flush in y)
    step = 1e-3
    xs = np.arange(-1.2, 1.2, step)
    path = [[x, 0.0, 0.99] for x in xs]
    r = sweep(CUBE, [1, 0, 0, 0], CUBE, [1, 0, 0, 0], path)
    # Then V = 0.01 (1 - |x|)^+ exactly and changes Lipschitz-wise; S = -dV/dx_A changes
    # Lipschitz-wise except where V has a kink (x = 0, where B's side faces pass A's, and
    # x = +-1, where the contact ends), and there only by the kink, 2 x 0.01 at most
    assert np.allclose(r[:, 0], 0.01 * np.clip(1 - np.abs(xs), 0, None), rtol=0, atol=1e-14)
    assert_lipschitz(r[:, :1], step, 0.0101)
    jumps = np.abs(np.diff(r[:, 1:], axis=0)).max(axis=1)
    assert np.all(jumps <= 1.01 * step + 0.0201)
    kinks = xs[1:][jumps > 1.01 * step + 1e-12]
    assert np.all(np.min(np.abs(kinks[:, None] - np.array([-1.0, 0.0, 1.0])[None, :]), axis=1) <= step)


def test_edge_to_edge_slide_is_continuous():
    # Given B turned so that its lower edge crosses A's upper edge at right angles
    # (A: edge along x at the top; B: edge along y), slid along the edge directions
    qa = quat([1, 0, 0], 45)
    qb = quat([0, 1, 0], 45)
    h = math.sqrt(0.5)
    step = 2e-3
    path = [[x, 0.3 * x, 2 * h - 0.02] for x in np.arange(-1.0, 1.0, step)]
    r = sweep(CUBE, qa, CUBE, qb, path)
    assert r[:, 0].max() > 0
    assert_lipschitz(r[:, :1], step, 0.05)
    assert_lipschitz(r[:, 1:], step, 2.0)


def test_random_rotation_sweep_is_continuous():
    # Given a random pair turned in small steps about a fixed axis while overlapping
    rng = np.random.default_rng(11)
    pa, pb, a, b, qa, qb = random_pair(rng, 0.01)
    xb = b.center - rotmat(qb) @ pb.centroid
    out = []
    for ang in np.arange(0.0, 2.0, 0.005):
        q = qmul(quat([1, 2, 0.5], ang), qb)
        v, g, s = polyhedron_overlap(a, place(pb, xb, q))
        assert np.isfinite(v) and np.all(np.isfinite(s)) and np.all(np.isfinite(g))
        out.append((v, *s))
    out = np.array(out)
    step = math.radians(0.005)
    assert_lipschitz(out[:, :1], step, 2.0)
    assert_lipschitz(out[:, 1:], step, 50.0)


def test_plate_20_to_1_on_cube_continuous_and_exact():
    # Given a 2 x 2 x 0.1 plate (20:1) lying 1e-3 deep on a cube, turned a little about z
    plate = box(2.0, 2.0, 0.1)
    step = 1e-3
    vs = []
    for x in np.arange(-1.6, 1.6, step):
        v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], plate, [x, 0.2, 0.5 + 0.05 - 1e-3],
                                          quat([0, 0, 1], 5))
        assert np.isfinite(v) and np.all(np.isfinite(n))
        vs.append((v, *s))
    vs = np.array(vs)
    assert_lipschitz(vs[:, :1], step, 2e-3)
    assert_lipschitz(vs[:, 1:], step, 4.0)
    # And with the plate centred the whole top face is in contact: V = 1e-3, S = z
    v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], plate, [0, 0, 0.55 - 1e-3],
                                      quat([0, 0, 1], 5))
    assert v == pytest.approx(1e-3, rel=1e-9, abs=0)
    assert rel(s, [0, 0, -1]) < 1e-12
    assert depth == pytest.approx(1e-3, rel=1e-9, abs=0)
    # And a plate standing on edge (thin side down) gives area 0.2 x 1 (clipped by the cube)
    v, g, s, *_ = contact(CUBE, np.zeros(3), [1, 0, 0, 0], plate, [0, 0, 0.5 + 1.0 - 1e-3], quat([1, 0, 0], 90))
    assert v == pytest.approx(1e-3 * 0.1 * 1.0, rel=1e-9, abs=0)
    assert rel(s, [0, 0, -0.1]) < 1e-9


@pytest.mark.parametrize("kind", ["face", "edge", "vertex"])
def test_overlap_of_1e_12_relative(kind):
    # Given contacts 1e-12 deep: face on face, edge on face, vertex on face
    eps = 1e-12
    if kind == "face":
        qb, zb = [1, 0, 0, 0], 1.0 - eps
    elif kind == "edge":
        qb, zb = quat([1, 0, 0], 45), 0.5 + math.sqrt(0.5) - eps
    else:
        qb = quat([1, -1, 0], math.degrees(math.acos(1 / math.sqrt(3))))
        zb = 0.5 + math.sqrt(3) / 2 - eps
    v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], CUBE, [0, 0, zb], qb)
    # Then V ~ 0 (at most eps x the face area), nothing is NaN and the normal is -z
    # (to 1e-4: the edge contact's S is 2e-12 long, its round-off ~1e-17)
    assert 0.0 <= v <= 2e-12
    assert np.all(np.isfinite(g)) and np.all(np.isfinite(s))
    assert np.isfinite(depth) and depth <= 1e-9
    assert rel(n, [0, 0, -1]) < 1e-4
    assert abs(g[2] - 0.5) < 1e-6


def test_touching_and_separated_give_zero():
    for zb in [1.0, 1.0 + 1e-13, 1.5, 3.0]:
        v, g, s, *_ = contact(CUBE, np.zeros(3), [1, 0, 0, 0], CUBE, [0.2, 0.1, zb], [1, 0, 0, 0])
        assert v == 0.0 and np.all(s == 0.0) and np.all(np.isfinite(g))


def test_small_cube_inside_big_one():
    # Given a cube of side 0.1 wholly inside a unit cube, off centre
    small = box(0.1, 0.1, 0.1)
    v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], small, [0.2, -0.1, 0.3],
                                      quat([1, 1, 1], 30))
    # Then V is the small volume, g its centre, S vanishes and the normal comes from the
    # centroid difference (A's centre minus B's), the depth stays finite
    assert v == pytest.approx(1e-3, rel=1e-12, abs=0)
    assert rel(g, [0.2, -0.1, 0.3]) < 1e-12
    assert np.abs(s).max() < 1e-14
    # (to 1e-4: S is round-off, ~1e-17, against the blend weight 1e-10 r_A r_B)
    assert rel(n, -np.array([0.2, -0.1, 0.3]) / np.linalg.norm([0.2, -0.1, 0.3])) < 1e-4
    assert np.isfinite(depth)
    # And with coincident centroids the normal is still a unit vector
    v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], small, np.zeros(3), [1, 0, 0, 0])
    assert np.linalg.norm(n) == pytest.approx(1.0, rel=1e-14, abs=0)


def test_contact_frame_matches_s_direction():
    # Given a random overlapping pair, Then contact_frame's normal is S/|S| to 1e-9
    rng = np.random.default_rng(21)
    _, _, a, b, _, _ = random_pair(rng, 0.01)
    v, g, s = polyhedron_overlap(a, b)
    nx, ny, nz, area, depth = contact_frame(v, *s, *a.center, *b.center, a.radius, b.radius)
    assert rel([nx, ny, nz], s / np.linalg.norm(s)) < 1e-9
    assert area == pytest.approx(np.linalg.norm(s), rel=1e-14, abs=0)
    assert depth == pytest.approx(v / np.linalg.norm(s), rel=1e-14, abs=0)


def test_random_pairs_symmetry_bounds_and_no_nan():
    # Given 60 random pairs from deep (one inside the other) to 1e-12 relative overlap
    rng = np.random.default_rng(31)
    for k in range(60):
        pa = random_polyhedron(rng, int(rng.integers(6, 25)), (1.0, rng.uniform(0.3, 1), rng.uniform(0.05, 1)))
        pb = random_polyhedron(rng, int(rng.integers(6, 25)), (1.0, rng.uniform(0.3, 1), rng.uniform(0.05, 1)))
        qa, qb = rng.normal(size=4), rng.normal(size=4)
        a = place(pa, rng.normal(size=3), qa)
        b = place(pb, a.center + rng.normal(size=3) * rng.choice([1e-3, 0.3, 1.0, 2.0]), qb)
        if k % 10 == 0:  # B shrunk into A's inscribed ball, deep inside A
            r_in = np.min(a.offsets - a.normals @ a.center)
            small = convex_hull((pb.vertices - pb.centroid) * 0.5 * r_in / b.radius)
            b = place(small, a.center, qb)
        v1, g1, s1 = polyhedron_overlap(a, b)
        v2, g2, s2 = polyhedron_overlap(b, a)
        # Then nothing is NaN, V is symmetric and bounded by the smaller volume, S flips,
        # and the centroid lies in both bodies
        assert np.isfinite(v1) and np.all(np.isfinite(g1)) and np.all(np.isfinite(s1))
        vmin = min(pa.volume, convex_hull(b.vertices).volume)
        assert 0.0 <= v1 <= vmin * (1 + 1e-12)
        assert v1 == pytest.approx(v2, rel=1e-12, abs=1e-14 * vmin)
        assert np.abs(s1 + s2).max() <= 1e-12 * max(1.0, np.abs(s1).max())
        if v1 > 1e-9 * vmin:
            assert rel(g1, g2) < 1e-9
            for p in (a, b):
                assert np.all(g1 @ p.normals.T - p.offsets <= 1e-9)
        if k % 10 == 0:
            assert v1 == pytest.approx(vmin, rel=1e-12, abs=0)
            assert np.abs(s1).max() < 1e-12


@pytest.mark.parametrize("axis", [[1, 0, 0], [1, 1, 0], [0.3, 0.2, 1]])
def test_nearly_parallel_faces_converge_to_the_aligned_case(axis):
    # Given B on A's top face 0.01 deep, turned by theta = 1e-13 .. 1e-3 rad about an axis:
    # its bottom face nearly parallel to A's top, its side faces nearly coplanar with A's
    delta = 0.01
    v0, g0, s0, *_ = contact(CUBE, np.zeros(3), [1, 0, 0, 0], CUBE, [0, 0, 1 - delta], [1, 0, 0, 0])
    for theta in 10.0 ** np.arange(-13.0, -2.5, 0.5):
        v, g, s, n, area, depth = contact(CUBE, np.zeros(3), [1, 0, 0, 0], CUBE, [0, 0, 1 - delta],
                                          quat(axis, math.degrees(theta)))
        # Then V, g and S . z differ from the aligned values by O(theta), with no jump at
        # any scale (the nearly coplanar side faces are counted once whatever their tilt);
        # S across z may differ by up to one side strip, delta x 1: V has a kink where B's
        # side faces pass A's, and the tilt moves it to an offset ~theta, so the one-sided
        # gradient is seen (at theta = 0 the two strips cancel)
        # (the tilt makes the slab's thickness vary by theta across it: its centroid moves
        # by theta / (12 delta) = 8.3 theta)
        assert abs(v - v0) <= 2 * theta * delta + 1e-14, (theta, v - v0)
        assert np.abs(g - g0).max() <= theta / (12 * delta) * 1.2 + 1e-11, (theta, g - g0)
        assert abs(s[2] - s0[2]) <= 6 * theta + 1e-12, (theta, s - s0)
        assert np.abs(s[:2] - s0[:2]).max() <= 1.01 * delta + 4 * theta, (theta, s - s0)
        assert n[2] < -0.9999


def test_nearly_coincident_copies_all_faces_nearly_coplanar():
    # Given a random polyhedron and a copy moved by eps and turned by eps rad (every face
    # nearly coplanar with its twin), eps = 1e-15 .. 1e-3
    rng = np.random.default_rng(1)
    for _ in range(12):
        p = random_polyhedron(rng, int(rng.integers(8, 30)), (1, rng.uniform(0.4, 1), rng.uniform(0.3, 1)))
        x0, q0 = np.array([0.3, -0.2, 0.1]), quat([1, 2, 3], 20)
        a = place(p, x0, q0)
        for eps in 10.0 ** np.arange(-15.0, -2.0):
            t = rng.normal(size=3)
            b = place(p, x0 + eps * t / np.linalg.norm(t), qmul(quat(rng.normal(size=3), math.degrees(eps)), q0))
            v, g, s = polyhedron_overlap(a, b)
            v2, *_ = polyhedron_overlap(b, a)
            # Then V lies between vol - 3 eps x (surface area) and vol, to 1e-12 relative,
            # and swapping A and B changes it by at most 1e-12 x the surface area (the tie
            # rule shifts the near-coplanar faces by tau ~ 1e-13 in favour of A)
            assert p.volume * (1 - 1e-12) - 3 * eps * p.areas.sum() <= v <= p.volume * (1 + 1e-12)
            assert v == pytest.approx(v2, rel=0, abs=1e-12 * p.areas.sum())


@pytest.mark.parametrize("seed", range(10))
def test_random_pairs_against_halfspace_intersection(seed):
    # Given a random pair with an overlap of 1e-4 .. 0.3 of the smaller volume
    rng = np.random.default_rng(300 + seed)
    _, _, a, b, _, _ = random_pair(rng, 10.0 ** rng.uniform(-4, np.log10(0.3)))
    v, g, s = polyhedron_overlap(a, b)
    # When the intersection is built independently: Qhull's half-space intersection about
    # the Chebyshev centre (a linear program), then exact mass properties of its hull
    normals = np.vstack([a.normals, b.normals])
    offsets = np.concatenate([a.offsets, b.offsets])
    res = linprog(c=[0, 0, 0, -1], A_ub=np.hstack([normals, np.ones((len(offsets), 1))]), b_ub=offsets,
                  bounds=[(None, None)] * 3 + [(0, None)])
    hs = HalfspaceIntersection(np.hstack([normals, -offsets[:, None]]), res.x[:3])
    ref = convex_hull(hs.intersections)
    # Then V and the centroid agree to 1e-11 (relative; of the overlap's size; measured
    # 2e-14 and 1e-15)
    size = np.ptp(hs.intersections, axis=0).max()
    assert v == pytest.approx(ref.volume, rel=1e-11, abs=0)
    assert np.abs(g - ref.centroid).max() < 1e-11 * size


@pytest.mark.parametrize("seed", range(5))
def test_random_wall_contacts_against_halfspace_intersection(seed):
    # Given a random polyhedron cut by a random wall 1e-3 .. 0.5 of its size deep
    rng = np.random.default_rng(400 + seed)
    p = random_polyhedron(rng, int(rng.integers(8, 30)), (1.0, rng.uniform(0.4, 1), rng.uniform(0.2, 1)))
    q = rng.normal(size=4)
    a = place(p, rng.normal(size=3), q / np.linalg.norm(q))
    nrm = rng.normal(size=3)
    nrm /= np.linalg.norm(nrm)
    low = (a.vertices @ nrm).min()
    wd = low + 10.0 ** rng.uniform(-3, np.log10(0.5)) * np.ptp(a.vertices @ nrm)
    v, g, s = polyhedron_plane_overlap(a, nrm, wd)
    # When the cut body is built by Qhull from A's planes and the wall's
    normals = np.vstack([a.normals, nrm])
    offsets = np.concatenate([a.offsets, [wd]])
    inner = a.vertices[np.argmin(a.vertices @ nrm)] * 0.999 + 0.001 * a.center
    inner = inner + 1e-3 * (a.center - inner)
    hs = HalfspaceIntersection(np.hstack([normals, -offsets[:, None]]), inner)
    ref = convex_hull(hs.intersections)
    on = hs.intersections[np.abs(hs.intersections @ nrm - wd) < 1e-9]
    # Then V and the centroid agree to 1e-11 and S is the cross-section area (Qhull's hull
    # of the points on the wall) times the normal
    size = np.ptp(hs.intersections, axis=0).max()
    assert v == pytest.approx(ref.volume, rel=1e-11, abs=0)
    assert np.abs(g - ref.centroid).max() < 1e-11 * size
    e1 = np.cross(nrm, [1.0, 0, 0] if abs(nrm[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(nrm, e1)
    cap = ConvexHull(np.stack([on @ e1, on @ e2], axis=1)).volume
    assert rel(s, cap * nrm) < 1e-10
