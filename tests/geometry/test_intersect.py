"""Separating-axis intersection test of convex polyhedra against obvious cases and an LP reference."""

import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from demcli.geometry import convex_hull, random_polyhedron
from demcli.geometry.intersect import as_convex, intersect, separation, transform

CUBE = np.array(list(itertools.product([-0.5, 0.5], repeat=3)))


def rot(axis, deg):
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def lp_overlap(a, b):
    """Reference: the largest t with n . x + t <= d for every face of both (t > 0: the interiors meet)."""
    pa, pb = convex_hull(a), convex_hull(b)
    normals = np.vstack([pa.normals, pb.normals])
    d = np.concatenate([pa.offsets, pb.offsets])
    a_ub = np.hstack([normals, np.ones((len(d), 1))])
    res = linprog(c=[0, 0, 0, -1], A_ub=a_ub, b_ub=d, bounds=[(None, None)] * 3 + [(None, 10.0)])
    return -res.fun


def test_cubes_apart_touching_and_overlapping():
    # Given two unit cubes along x with gaps of 0.5, 0 and -0.2
    for gap, hit in [(0.5, False), (0.0, False), (-0.2, True)]:
        value, axis = separation(CUBE, CUBE + [1.0 + gap, 0, 0])
        # Then the separation is the gap (the penetration depth when negative), along +x
        assert value == pytest.approx(gap, abs=1e-12)
        assert abs(axis[0]) == pytest.approx(1.0)
        assert intersect(CUBE, CUBE + [1.0 + gap, 0, 0]) is hit


def test_penetration_depth_is_the_shortest_separating_move():
    # Given cubes overlapping by 0.3 along x and 0.1 along y
    value, axis = separation(CUBE, CUBE + [0.7, 0.9, 0.0])
    # Then the depth is the smaller overlap, along y, pointing from a to b
    assert value == pytest.approx(-0.1, abs=1e-12)
    assert np.allclose(axis, [0, 1, 0])


def test_edge_edge_case_needs_the_cross_product_axes():
    # Given a cube turned 45 deg about z (an edge along z at x = sqrt 2 / 2) and one turned
    # 45 deg about y (an edge along y at x = -sqrt 2 / 2 from its centre), edges crossing
    a = as_convex(CUBE @ rot(2, 45).T)
    for gap in (0.01, -0.01):
        b = transform(CUBE, rot(1, 45), [np.sqrt(2) + gap, 0.0, 0.0])
        # When only face normals are tried, they never separate the two
        axes = np.vstack([a.normals, b.normals])
        pa, pb = a.vertices @ axes.T, b.vertices @ axes.T
        face_only = np.max(np.maximum(pb.min(0) - pa.max(0), pa.min(0) - pb.max(0)))
        assert face_only < 0.0
        # Then the full test finds the edge-edge axis x and the exact gap (or depth)
        value, axis = separation(a, b)
        assert value == pytest.approx(gap, abs=1e-12)
        assert np.allclose(np.abs(axis), [1, 0, 0], atol=1e-12)
        assert intersect(a, b) is (gap < 0)


def test_random_pairs_agree_with_linear_programming():
    # Given random convex polyhedra at random offsets
    rng = np.random.default_rng(5)
    agree = tested = 0
    for _ in range(150):
        a = random_polyhedron(rng, int(rng.integers(6, 16)), rng.uniform(0.3, 1.0, 3)).vertices
        b = random_polyhedron(rng, int(rng.integers(6, 16)), rng.uniform(0.3, 1.0, 3)).vertices
        b = b @ rot(int(rng.integers(3)), rng.uniform(0, 180)).T + rng.uniform(-1.6, 1.6, 3)
        t = lp_overlap(a, b)
        if abs(t) < 1e-7:  # grazing: round-off decides either way
            continue
        tested += 1
        agree += intersect(a, b) == (t > 0)
    # Then SAT and the LP give the same answer every time, on a good mix of both outcomes
    assert tested > 120 and agree == tested


def test_tolerance_accepts_shallow_overlaps_and_demands_gaps():
    b = CUBE + [0.99, 0, 0]  # 0.01 overlap
    assert intersect(CUBE, b) and not intersect(CUBE, b, tol=0.02)
    c = CUBE + [1.01, 0, 0]  # 0.01 gap
    assert not intersect(CUBE, c) and intersect(CUBE, c, tol=-0.02)
