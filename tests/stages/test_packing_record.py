"""The packing record (output.packing): the exact parts of spheres, disks and polyhedra inside a
box against closed forms, quadrature and Monte Carlo; rattlers and coordination on hand-placed
scenes; a short settling run whose record matches a brute-force reading of its final state; and
a resumed run that continues the record bit for bit."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from demcli import run_case
from demcli.compare import read_record
from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls
from demcli.errors import ConfigError, InputError
from demcli.geometry import convex_hull, random_polyhedron
from demcli.geometry.window import (convex_box_volume, disk_rectangle_area, sphere_box_volume, sphere_lens)
from demcli.stages.packing_record import COLUMNS, PackingProbe, check_scene, contact_counts
from demcli.state import read_state

BALL = 4.0 / 3.0 * math.pi


def _mc(rng, inside, lo, hi, n=1_000_000):
    """(estimate, standard error) of the volume of {inside(points)} in the box [lo, hi]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    frac = float(np.mean(inside(rng.uniform(lo, hi, (n, len(lo))))))
    vol = float(np.prod(hi - lo))
    return frac * vol, math.sqrt(max(frac * (1.0 - frac), 1.0 / n) / n) * vol


# ---- disks and rectangles -----------------------------------------------------------------------

def test_disk_rectangle_area_closed_forms_and_monte_carlo():
    r = 1.3
    area = lambda c, lo, hi: float(disk_rectangle_area([c], [r], lo, hi)[0])  # noqa: E731
    # a disk inside, a half-plane segment r^2 acos(d/r) - d sqrt(r^2 - d^2), a quadrant, outside
    assert area((0, 0), (-5, -5), (5, 5)) == pytest.approx(math.pi * r * r, rel=1e-15)
    for d in (-1.2, -0.4, 0.0, 0.3, 1.1):
        seg = r * r * math.acos(d / r) - d * math.sqrt(r * r - d * d)
        assert area((0, 0), (d, -5), (5, 5)) == pytest.approx(seg, rel=1e-14, abs=1e-15)
    assert area((0, 0), (0, 0), (5, 5)) == pytest.approx(math.pi * r * r / 4, rel=1e-15)
    assert area((0, 0), (1.3, -5), (5, 5)) == 0.0
    # random rectangles cutting a disk: within 5 standard errors of 10^6 samples
    rng = np.random.default_rng(1)
    for _ in range(6):
        lo = rng.uniform(-1.6, 0.5, 2)
        hi = lo + rng.uniform(0.2, 2.5, 2)
        c = rng.uniform(-0.3, 0.3, 2)
        ref, err = _mc(rng, lambda p: ((p - c) ** 2).sum(axis=1) <= r * r, lo, hi)
        assert abs(area(c, lo, hi) - ref) < 5 * err


# ---- balls and boxes ----------------------------------------------------------------------------

def _quadrature_ball_box(c, r, lo, hi, nodes=40):
    """int A(z) dz of the exact disk-rectangle area over the ball's slices: Gauss-Legendre on the
    pieces between the heights where a slice's circle meets a side or a corner of the rectangle,
    mapped by z = a + h (3 s^2 - 2 s^3) so that the end points' square-root kinks are smooth."""
    ds = [abs(lo[0] - c[0]), abs(hi[0] - c[0]), abs(lo[1] - c[1]), abs(hi[1] - c[1])]
    ds += [math.hypot(x, y) for x in ds[:2] for y in ds[2:]]
    za, zb = max(lo[2], c[2] - r), min(hi[2], c[2] + r)
    if zb <= za:
        return 0.0
    pts = {za, zb} | ({c[2]} if za < c[2] < zb else set())
    for d in ds:
        if d < r:
            pts |= {z for z in (c[2] - math.sqrt(r * r - d * d), c[2] + math.sqrt(r * r - d * d)) if za < z < zb}
    s, w = np.polynomial.legendre.leggauss(nodes)
    s, w = (s + 1) / 2, w / 2
    total = 0.0
    pts = sorted(pts)
    for a, b in zip(pts[:-1], pts[1:]):
        z = a + (b - a) * (3 * s * s - 2 * s ** 3)
        rho = np.sqrt(np.maximum(r * r - (z - c[2]) ** 2, 0.0))
        total += float(np.sum(w * disk_rectangle_area(np.tile(c[:2], (nodes, 1)), rho, lo[:2], hi[:2])
                              * (b - a) * 6 * s * (1 - s)))
    return total


def test_sphere_box_volume_closed_forms():
    r = 0.7
    vol = lambda lo, hi, c=(0, 0, 0): float(sphere_box_volume([c], [r], lo, hi)[0])  # noqa: E731
    big = 10.0
    assert vol((-big,) * 3, (big,) * 3) == BALL * r ** 3                        # wholly inside
    assert vol((1, -big, -big), (big, big, big)) == 0.0                         # wholly outside
    for h in (0.0, 0.05, 0.3, 0.7, 1.1, 1.4):                                   # the cap pi h^2 (3R - h) / 3
        cap = math.pi * h * h * (3 * r - h) / 3
        assert vol((-big, -big, r - h), (big,) * 3) == pytest.approx(cap, rel=1e-13, abs=1e-16)
    assert vol((0, 0, 0), (big,) * 3) == pytest.approx(BALL * r ** 3 / 8, rel=1e-14)      # octant
    assert vol((0, 0, -big), (big,) * 3) == pytest.approx(BALL * r ** 3 / 4, rel=1e-14)   # quarter
    assert vol((-big, -big, 0), (big,) * 3) == pytest.approx(BALL * r ** 3 / 2, rel=1e-14)  # half
    for k in range(8):  # every octant, its faces through the centre from either side (-0.0 offsets)
        lo = [0.0 if (k >> d) & 1 else -big for d in range(3)]
        hi = [big if (k >> d) & 1 else 0.0 for d in range(3)]
        assert vol(lo, hi) == pytest.approx(BALL * r ** 3 / 8, rel=1e-14)
    # the eight boxes meeting at any point part the ball: their volumes add up to it
    rng = np.random.default_rng(2)
    for _ in range(20):
        p, c = rng.uniform(-0.8, 0.8, 3), rng.uniform(-0.3, 0.3, 3)
        total = 0.0
        for k in range(8):
            bits = [(k >> d) & 1 for d in range(3)]
            lo = [p[d] if bits[d] else -big for d in range(3)]
            hi = [big if bits[d] else p[d] for d in range(3)]
            total += vol(lo, hi, c)
        assert total == pytest.approx(BALL * r ** 3, rel=1e-14)


def test_sphere_box_volume_against_quadrature_and_monte_carlo():
    rng = np.random.default_rng(3)
    r = 1.0
    # Given random boxes cutting a ball (across faces, edges and corners)
    for _ in range(40):
        c = rng.uniform(-0.5, 0.5, 3)
        lo = rng.uniform(-1.4, 0.4, 3)
        hi = lo + rng.uniform(0.1, 2.0, 3)
        v = float(sphere_box_volume([c], [r], lo, hi)[0])
        # Then the closed form is the quadrature of the slices' exact areas to 1e-13 of the ball
        assert v == pytest.approx(_quadrature_ball_box(c, r, lo, hi), abs=1e-13 * BALL)
    # and Monte Carlo (10^6 samples in the box around the ball) within 5 standard errors
    for _ in range(4):
        c = rng.uniform(-0.5, 0.5, 3)
        lo = rng.uniform(-1.2, 0.2, 3)
        hi = lo + rng.uniform(0.5, 1.5, 3)
        a, b = np.maximum(lo, c - r), np.minimum(hi, c + r)
        ref, err = _mc(rng, lambda p: ((p - c) ** 2).sum(axis=1) <= r * r, a, b)
        assert abs(float(sphere_box_volume([c], [r], lo, hi)[0]) - ref) < 5 * err


def test_sphere_lens_against_monte_carlo():
    rng = np.random.default_rng(4)
    for r1, r2, d in ((1.0, 1.0, 1.0), (1.0, 0.6, 1.2), (0.7, 1.1, 0.9)):
        w, t = sphere_lens(r1, r2, d)
        inside = lambda p: ((p ** 2).sum(axis=1) <= r1 * r1) & (((p - [d, 0, 0]) ** 2).sum(axis=1) <= r2 * r2)  # noqa
        ref, err = _mc(rng, inside, [-r1] * 3, [r1] * 3)
        assert abs(float(w) - ref) < 5 * err
        p = rng.uniform(-r1, r1, (1_000_000, 3))
        assert float(t) == pytest.approx(p[inside(p), 0].mean(), abs=3e-3)
    assert sphere_lens(1.0, 0.3, 0.5) == pytest.approx((BALL * 0.027, 0.5))   # the small ball inside
    assert sphere_lens(1.0, 0.3, 1.3)[0] == 0.0


# ---- convex polyhedra and boxes -----------------------------------------------------------------

def _clip(poly, lo, hi):
    return convex_box_volume(poly.vertices, poly.edges, poly.normals, poly.offsets, lo, hi)


def test_convex_box_volume():
    cube = convex_hull(np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float))
    # a cube and a box: the box of their overlap (1e-14)
    assert _clip(cube, [0.5, 0.2, -1], [2, 0.7, 0.4]) == pytest.approx(0.5 * 0.5 * 0.4, rel=1e-14)
    assert _clip(cube, [0.2, 0.2, 0.2], [0.3, 0.4, 0.5]) == pytest.approx(0.1 * 0.2 * 0.3, rel=1e-13)
    assert _clip(cube, [-1] * 3, [2] * 3) == pytest.approx(1.0, rel=1e-14)
    assert _clip(cube, [2] * 3, [3] * 3) == 0.0
    # a random polyhedron: the eight boxes at a point part it (1e-13), Monte Carlo within 5 errors
    rng = np.random.default_rng(5)
    poly = random_polyhedron(rng, 30, (1.0, 0.7, 0.5))
    p = rng.uniform(-0.3, 0.3, 3)
    total = sum(_clip(poly, [p[d] if (k >> d) & 1 else -5 for d in range(3)],
                      [5 if (k >> d) & 1 else p[d] for d in range(3)]) for k in range(8))
    assert total == pytest.approx(poly.volume, rel=1e-13)
    for _ in range(3):
        lo = rng.uniform(-1, 0.3, 3)
        hi = lo + rng.uniform(0.3, 1.5, 3)
        a, b = np.maximum(lo, poly.vertices.min(axis=0)), np.minimum(hi, poly.vertices.max(axis=0))
        ref, err = _mc(rng, lambda q: np.all(q @ poly.normals.T <= poly.offsets, axis=1), a, b)
        assert abs(_clip(poly, lo, hi) - ref) < 5 * err


# ---- the probe on hand-placed scenes ------------------------------------------------------------

MAT = [Material("glass", 2500.0)]


def _spec(window=None, margin=None, around=None, min_contacts=None):
    win = None if window is None else SimpleNamespace(min=window[0], max=window[1])
    return SimpleNamespace(window=win, margin=margin, around=around, min_contacts=min_contacts)


def _touching(x, r, sbody, walls, wpoint, gap=1e-9):
    """Stored contact groups of the sphere pairs and sphere-plane pairs closer than ``gap``."""
    i, j = np.triu_indices(len(r), 1)
    near = (np.linalg.norm(x[i] - x[j], axis=1) <= r[i] + r[j] + gap) & (sbody[i] != sbody[j])
    contacts = {"i": i[near], "j": j[near], "force": np.ones((near.sum(), 3))}
    s, w = np.meshgrid(np.arange(len(r)), np.arange(len(walls)), indexing="ij")
    s, w = s.ravel(), w.ravel()
    dist = np.einsum("ij,ij->i", x[s] - wpoint[w], walls.normal[w])
    hit = dist <= r[s] + gap
    return contacts, {"sphere": s[hit], "wall": w[hit], "force": np.ones((hit.sum(), 3))}


def _sphere_scene(x, r, walls=None, sbody=None, soff=None, mass=None, flags=None):
    """A System (not stepped: no kernel compiled) of spheres or clumps (body positions ``x`` when
    ``sbody`` is given) whose stored contacts are the touching pairs."""
    x, r = np.asarray(x, float).reshape(-1, 3), np.asarray(r, float)
    walls = Walls() if walls is None else walls
    clumps = sbody is not None
    sbody = np.arange(len(r)) if sbody is None else np.asarray(sbody, np.int64)
    soff = np.zeros((len(r), 3)) if soff is None else np.asarray(soff, float)
    nb = len(x)
    m = np.bincount(sbody, weights=2500.0 * BALL * r ** 3, minlength=nb) if mass is None else np.asarray(mass)
    bodies = {"x": x, "v": np.zeros((nb, 3)), "omega": np.zeros((nb, 3)), "q": np.tile([1.0, 0, 0, 0], (nb, 1)),
              "mass": m, "inertia": np.ones((nb, 3)) * 1e-6, "id": np.arange(nb),
              "flags": np.zeros(nb, np.int8) if flags is None else np.asarray(flags, np.int8)}
    contacts, wall_contacts = _touching(x[sbody] + soff, r, sbody, walls, np.asarray(walls.point))
    groups = {"bodies": bodies, "spheres": {"body": sbody, "offset": soff, "radius": r,
                                            "material": np.zeros(len(r), np.int64)},
              "contacts": contacts, "wall_contacts": wall_contacts}
    return System(groups, MAT, ContactModel(), make_plan([], clumps=clumps, walls=len(walls) > 0), walls,
                  Dynamics(), dt=1.0)


def test_simple_cubic_lattice_and_a_rattler():
    # Given a simple cubic lattice of touching spheres (d = 1) filling a box of walls [0, 5]^3
    g = np.arange(5) + 0.5
    x = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    walls = Walls.box_faces((5.0, 5.0, 5.0))
    s = _sphere_scene(x, np.full(len(x), 0.5), walls)
    # When a window whose faces lie on the lattice's planes of centres is sampled
    probe = PackingProbe(s, _spec(window=((0.5,) * 3, (3.5,) * 3)), False, 1.0, 1.0)
    row = probe.row(s)
    # Then its solid fraction is pi / 6, every body has 6 contacts (neighbours and walls), none rattles
    assert row["solid_fraction"] == pytest.approx(math.pi / 6, rel=1e-13)
    assert (row["bodies"], row["coordination"], row["raw_coordination"], row["rattler_fraction"]) == (64, 6.0, 6.0,
                                                                                                      0.0)
    # Given a loose small sphere in a cell's centre: it is a rattler (it touches nothing)
    s = _sphere_scene(np.vstack([x, [1.0, 1.0, 1.0]]), np.r_[np.full(len(x), 0.5), 0.1], walls)
    row = PackingProbe(s, _spec(window=((0.5,) * 3, (3.5,) * 3)), False, 1.0, 1.0).row(s)
    assert row["solid_fraction"] == pytest.approx((27 * math.pi / 6 + BALL * 0.1 ** 3) / 27, rel=1e-13)
    assert (row["bodies"], row["coordination"], row["rattler_fraction"]) == (65, 6.0, 1 / 65)
    assert row["raw_coordination"] == pytest.approx(64 * 6 / 65)
    # And the default window, 2 d (d = 0.5 here) inside the bodies' box [0, 5]^3, is [1, 4]^3: 27
    # whole spheres and an eighth of the small one
    row = PackingProbe(s, _spec(), False, 1.0, 0.5).row(s)
    assert [row[k] for k in ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")] == [1.0, 1.0, 1.0, 4.0, 4.0, 4.0]
    assert row["solid_fraction"] == pytest.approx((27 * math.pi / 6 + BALL * 0.1 ** 3 / 8) / 27, rel=1e-13)
    assert row["bodies"] == 28


def test_rattlers_are_removed_until_none_is_left():
    # Given bodies 0..4 all touching each other (4 contacts each), body 5 touching 0, 1 and 6
    # (3: a rattler), body 6 touching 5, 0, 1, 2 (4, then 3 once 5 is gone), body 7 touching 3, 4
    # and two walls (4), body 8 held fixed with one contact, and body 9 with no contact
    pairs = [(a, b) for a in range(5) for b in range(a + 1, 5)] + [(0, 5), (1, 5), (5, 6), (0, 6), (1, 6),
                                                                      (2, 6), (3, 7), (4, 7), (4, 8)]
    held = np.zeros(10, bool)
    held[8] = True
    z0, z, rattler = contact_counts(10, pairs, [7, 7], 4, held)
    # Then 5, 6 and 9 rattle; 8 is held; the others keep their contacts but those with rattlers
    assert rattler.tolist() == [False] * 5 + [True, True, False, False, True]
    assert z0.tolist() == [6, 6, 5, 5, 6, 3, 4, 4, 1, 0]
    assert z[~rattler].tolist() == [4, 4, 4, 5, 6, 4, 1]
    # a lower bar keeps them (5 has 3 contacts)
    assert not contact_counts(10, pairs, [7, 7], 3, held)[2][:9].any()


def _two_ball_clump(d):
    """(offsets, radii, union volume) of a clump of two unit balls at distance d."""
    lens = math.pi * (4 + d) * (2 - d) ** 2 / 12
    return np.array([[-d / 2, 0, 0], [d / 2, 0, 0]]), np.ones(2), 2 * BALL - lens


def test_clumps_count_one_contact_per_body_pair_and_their_union_volume():
    # Given two clumps of two unit balls (d = 1) side by side along y, touching at both member pairs
    off, r, vol = _two_ball_clump(1.0)
    x = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    s = _sphere_scene(x, np.tile(r, 2), sbody=[0, 0, 1, 1], soff=np.vstack([off, off]),
                      mass=np.full(2, 2500.0 * vol))
    probe = PackingProbe(s, _spec(window=((-5, -5, -5), (5, 5, 5)), min_contacts=1), False, 1.0, 1.0)
    # Then the two clumps are one contact, and a window holding them has their union volume
    assert probe.body_contacts(s)[0].tolist() == [[0, 1]]
    row = probe.row(s)
    assert row["raw_coordination"] == 1.0
    assert row["solid_fraction"] * 1000 == pytest.approx(2 * vol, rel=1e-12)
    # a window cutting both through their middle x = 0 (the lenses in halves) has half of it
    half = PackingProbe(s, _spec(window=((0, -5, -5), (5, 5, 5))), False, 1.0, 1.0)
    assert half.solid_volume(s, np.array([0.0, -5, -5]), np.array([5.0, 5, 5])) == pytest.approx(vol, rel=1e-12)


def test_a_cut_clump_is_within_two_percent_of_its_exact_part():
    # Given one clump of two unit balls a radius apart (the lens they share is 19 % of the clump)
    # and windows cutting it across and along its axis, its exact part by Monte Carlo (10^6
    # samples, standard error <= 0.15 % of the clump)
    rng = np.random.default_rng(6)
    off, r, vol = _two_ball_clump(1.0)
    s = _sphere_scene([[0.0, 0.0, 0.0]], r, sbody=[0, 0], soff=off, mass=[2500.0 * vol])
    probe = PackingProbe(s, _spec(window=((-9, -9, -9), (9, 9, 9))), False, 1.0, 1.0)
    inside = lambda p: np.minimum(((p - off[0]) ** 2).sum(axis=1), ((p - off[1]) ** 2).sum(axis=1)) <= 1.0  # noqa
    extent = np.array([[-1.5, -1.0, -1.0], [1.5, 1.0, 1.0]])
    worst = 0.0
    for axis in (0, 1):
        for a in np.linspace(-0.8, 0.8, 7) * extent[1][axis]:
            lo, hi = np.full(3, -3.0), np.full(3, 3.0)
            lo[axis] = a
            ref, _ = _mc(rng, inside, np.maximum(lo, extent[0]), extent[1])
            worst = max(worst, abs(probe.solid_volume(s, lo, hi) - ref) / vol)
    # Then the lens taken as the ball of its volume at its centroid errs by less than 2.5 % of the
    # clump (1.6 % measured, for cuts through the lens; sharing the lens out by the members'
    # parts instead would err by up to 16 %)
    assert worst < 0.025


def test_window_around_the_walls_and_in_2d():
    # Given disks (z = 0) of a square lattice, d = 1, touching, in a box of walls [0, 6] x [0, 6], open at y1
    g = np.arange(6) + 0.5
    x = np.array([[a, b, 0.0] for a in g for b in g])
    walls = Walls.fixed_planes([(0, 0, 0), (6, 0, 0), (0, 0, 0)], [(1, 0, 0), (-1, 0, 0), (0, 1, 0)])
    s = _sphere_scene(x, np.full(len(x), 0.5), walls)
    # When the window is the walls' box less 1 d (the open side: the bodies' extent, y = 6)
    probe = PackingProbe(s, _spec(margin=1.0, around="walls"), True, 1.0, 1.0)
    row = probe.row(s)
    # Then it is [1, 5] x [1, 5], its area fraction pi / 4, and each disk has 4 contacts (3 is the 2D bar)
    assert [row[k] for k in ("xmin", "ymin", "xmax", "ymax")] == [1.0, 1.0, 5.0, 5.0]
    assert row["solid_fraction"] == pytest.approx(math.pi / 4, rel=1e-13)
    assert (row["bodies"], row["coordination"], row["rattler_fraction"]) == (16, 4.0, 0.0)
    assert probe.min_contacts == 3


def test_polyhedra_cut_exactly_and_mixed_scenes_are_refused():
    from demcli.engine.poly_shape import polyhedra_groups

    # Given two unit cubes turned 45 degrees about z, at x = 0 and x = 3 (the second out of the window)
    cube = convex_hull(np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)], float))
    turn = [math.cos(math.pi / 8), 0, 0, math.sin(math.pi / 8)]
    groups = polyhedra_groups([cube, cube], 2500.0, x=[[0, 0, 0], [3, 0, 0]], q=[turn, turn])
    groups["body_contacts"] = {"i": np.array([0]), "j": np.array([1]), "force": np.ones((1, 3)),
                               "depth": np.array([1e-6])}
    s = System(groups, MAT, ContactModel(), make_plan([], polyhedra=True), Walls(), Dynamics(), dt=1.0)
    probe = PackingProbe(s, _spec(window=((0.2, -1, -1), (1, 1, 1)), min_contacts=1), False, 1.0, 1.0)
    # Then the part beyond x = 0.2 is the prism of the diamond's corner: (sqrt(2)/2 - 0.2)^2 x 1
    part = (math.sqrt(2) / 2 - 0.2) ** 2
    assert probe.solid_volume(s, np.array([0.2, -1, -1]), np.array([1.0, 1, 1])) == pytest.approx(part, rel=1e-12)
    assert probe.body_contacts(s)[0].tolist() == [[0, 1]]
    # a scene of spheres with polyhedra is refused
    with pytest.raises(InputError, match="spheres with polyhedra"):
        check_scene(SimpleNamespace(plugin=SimpleNamespace(name="mixed")))


def test_settings_are_checked_by_key(tmp_path):
    from demcli.stages.base import load_case

    path = tmp_path / "case.yaml"
    path.write_text(CASE)
    bad = {"stages.settle.output.packing={window: {min: [0, 0, 0], max: [1, 1, 1]}, margin: 1}":
           "stages[1].output.packing.margin: give a window or a margin, not both",
           "stages.settle.output.packing={window: {min: [0, 0, 0], max: [1, 1, 1]}, around: walls}":
           "stages[1].output.packing.around: is the box a margin shrinks",
           "stages.settle.output.packing={window: {min: [0, 0, 0], max: [1, -1, 1]}}":
           "stages[1].output.packing.window.max[1]: must be > min",
           "stages.settle.output.packing={min_contacts: 0}": "stages[1].output.packing.min_contacts: must be >= 1",
           "stages.settle.output.packing={around: wall}": "stages[1].output.packing.around: must be one of"}
    for override, message in bad.items():
        with pytest.raises(ConfigError) as info:
            load_case(path, [override])
        assert message in str(info.value), str(info.value)


# ---- a settling run -----------------------------------------------------------------------------

# the beads smoke case, poured lower and settled under 10 g so that its 3000 steps make a bed
CASE = """\
name: packing
seed: 7
materials:
  glass: {density: 2500 kg/m^3, young: 50 MPa, poisson: 0.25, friction: 0.5, restitution: 0.6}
  steel: {density: 7800 kg/m^3, young: 200 GPa, poisson: 0.3, friction: 0.3, restitution: 0.6}
stages:
  - name: pour
    type: generate
    region: {shape: box, min: [1 mm, 1 mm, 1 mm], max: [14 mm, 14 mm, 24 mm]}
    count: 150
    radius: {min: 1.0 mm, max: 1.5 mm}
    material: glass
  - name: settle
    type: dem
    physics: {gravity: [0, 0, -98.1], friction: true}
    walls:
      - {type: box, min: [0, 0, 0], max: [15 mm, 15 mm, 40 mm], material: steel, open: [z1]}
    time: {steps: 3000, dt_factor: 0.25}
    output: {records: 10, snapshots: 0, packing: {margin: 1, min_contacts: 3}}
"""


@pytest.fixture(scope="module")
def settled(tmp_path_factory):
    folder = tmp_path_factory.mktemp("packing")
    (folder / "case.yaml").write_text(CASE)
    run_case(folder / "case.yaml", out=folder / "run", quiet=True)
    return folder


def _naive_coordination(state, lo, hi, min_contacts):
    """Mean contacts of the non-rattlers centred in [lo, hi], by repeated sweeps over sets."""
    g = state.groups
    nb = len(g["bodies"]["mass"])
    nbrs = {b: set() for b in range(nb)}
    for i, j in zip(g["contacts"]["i"].tolist(), g["contacts"]["j"].tolist()):
        nbrs[i].add(j)
        nbrs[j].add(i)
    walls = {b: set() for b in range(nb)}
    for b, w in zip(g["wall_contacts"]["sphere"].tolist(), g["wall_contacts"]["wall"].tolist()):
        walls[b].add(w)
    gone = set()
    while True:
        drop = {b for b in range(nb) if b not in gone and len(nbrs[b] - gone) + len(walls[b]) < min_contacts}
        if not drop:
            break
        gone |= drop
    x = g["bodies"]["x"]
    inside = [b for b in range(nb) if np.all(x[b] >= lo) and np.all(x[b] <= hi)]
    kept = [len(nbrs[b] - gone) + len(walls[b]) for b in inside if b not in gone]
    return float(np.mean(kept)), len(inside), sum(b in gone for b in inside)


def test_the_record_of_a_settling_run_matches_its_final_state(settled):
    run = settled / "run"
    rec, _ = read_record(run / "records" / "settle_packing.csv")
    # Then the CSV has the columns, a row per record, values in range
    assert list(rec) == list(COLUMNS)
    assert len(rec["time"]) == 11 and rec["step"][-1] == 3000
    assert np.all((rec["solid_fraction"] > 0) & (rec["solid_fraction"] < 0.75))
    assert np.all((rec["rattler_fraction"] >= 0) & (rec["rattler_fraction"] <= 1)) and np.all(rec["bodies"] > 0)
    last = {k: v[-1] for k, v in rec.items()}
    assert 3.0 <= last["coordination"] <= 8.0 and 0.0 < last["raw_coordination"] <= 8.0
    state = read_state(run / "01-settle.h5")
    assert "records/packing" in state.groups
    lo = np.array([last["xmin"], last["ymin"], last["zmin"]])
    hi = np.array([last["xmax"], last["ymax"], last["zmax"]])
    # the window is the bodies' box less d on each side
    x, r = state.groups["bodies"]["x"], state.groups["spheres"]["radius"]
    d = 2 * r.mean()
    assert lo == pytest.approx((x - r[:, None]).min(axis=0) + d, abs=1e-15)
    assert hi == pytest.approx((x + r[:, None]).max(axis=0) - d, abs=1e-15)
    # And its solid fraction is the share of 10^6 random points of the window inside a sphere
    # (5 standard errors, about 2.5e-3)
    rng = np.random.default_rng(8)
    p = rng.uniform(lo, hi, (1_000_000, 3))
    hit = np.zeros(len(p), bool)
    for c, rc in zip(x, r):
        if np.all(c + rc > lo) and np.all(c - rc < hi):
            hit |= ((p - c) ** 2).sum(axis=1) <= rc * rc
    f = hit.mean()
    assert abs(last["solid_fraction"] - f) < 5 * math.sqrt(f * (1 - f) / len(p))
    # and its coordination and rattlers those of a naive removal on the state's contact lists
    z, n, rattlers = _naive_coordination(state, lo, hi, 3)
    assert (last["coordination"], last["bodies"], last["rattler_fraction"]) == (pytest.approx(z, rel=1e-14), n,
                                                                                 pytest.approx(rattlers / n))


def test_a_resumed_run_continues_the_record(settled, tmp_path, interrupt_and_resume, h5_datasets):
    # Given the run interrupted at step 1500 and resumed
    (tmp_path / "case.yaml").write_text(CASE)
    interrupt_and_resume(System, 1500, tmp_path / "case.yaml", tmp_path / "run", "01-settle.ckpt.h5")
    # Then the packing record is the uninterrupted one, bit for bit
    name = "records/settle_packing.csv"
    assert (tmp_path / "run" / name).read_text() == (settled / "run" / name).read_text()
    a, b = h5_datasets(tmp_path / "run" / "01-settle.h5"), h5_datasets(settled / "run" / "01-settle.h5")
    for key in (k for k in a if k.startswith("records/packing")):
        assert np.array_equal(a[key], b[key], equal_nan=True), key
