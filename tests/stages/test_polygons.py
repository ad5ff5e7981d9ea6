"""Polygons stage (seed 001): random convex polygons placed without intersection.

Checked against naive references written here: Sutherland-Hodgman clipping for the
intersection area of two convex polygons (instead of the kernel's separating axes) and
scipy's Qhull for hulls (instead of the kernel's Graham scan).
"""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.geometry import convex_hull_2d, polygon_area
from demcli.geometry.section2d import Specimen, graham_hull, place_polygons, polygons_overlap
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"
AC13_SIEVES = np.array([1.18, 2.36, 4.75, 9.5, 13.2, 16, 19, 26.5, 31.5]) * 1e-3
AC13_PASSING = np.array([26.4, 37.6, 49.8, 79.7, 95, 100, 100, 100, 100])


# ---------------------------------------------------------------------------------------
# naive references
# ---------------------------------------------------------------------------------------
def clip_area(a, b):
    """Area of the intersection of convex CCW polygons a and b (Sutherland-Hodgman)."""
    out = [tuple(p) for p in a]
    for i in range(len(b)):
        p, q = b[i], b[(i + 1) % len(b)]
        inp, out = out, []
        if not inp:
            break

        def side(x):
            return (q[0] - p[0]) * (x[1] - p[1]) - (q[1] - p[1]) * (x[0] - p[0])

        for k in range(len(inp)):
            cur, prev = inp[k], inp[k - 1]
            sc, sp = side(cur), side(prev)
            if sc >= 0:
                if sp < 0:
                    t = sp / (sp - sc)
                    out.append((prev[0] + t * (cur[0] - prev[0]), prev[1] + t * (cur[1] - prev[1])))
                out.append(cur)
            elif sp >= 0:
                t = sp / (sp - sc)
                out.append((prev[0] + t * (cur[0] - prev[0]), prev[1] + t * (cur[1] - prev[1])))
    if len(out) < 3:
        return 0.0
    x, y = np.array(out).T
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def random_convex(rng, centre, radius, m=8):
    t = np.sort(rng.uniform(0, 2 * np.pi, m))
    pts = centre + radius * rng.uniform(0.3, 1.0, (m, 1)) * np.stack([np.cos(t), np.sin(t)], axis=1)
    return convex_hull_2d(pts)


def strictly_convex_ccw(p):
    e = np.roll(p, -1, axis=0) - p
    cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
    return len(p) >= 3 and bool(np.all(cross > 0))


def ac13_targets(specimen, fraction=None):
    v_ag = 0.9515 / 2640
    v_z = (v_ag + 0.0485 / 1100) / 0.96
    m = v_ag / v_z * (100 - 26.4) / 100
    share = np.diff(AC13_PASSING) / (100 - 26.4)
    return specimen.area * (m if fraction is None else fraction) * share


# ---------------------------------------------------------------------------------------
# kernels against the references
# ---------------------------------------------------------------------------------------
def test_graham_scan_matches_qhull():
    # Given random point clouds, with duplicates and collinear points mixed in
    rng = np.random.default_rng(3)
    for k in range(600):
        pts = rng.normal(size=(rng.integers(3, 14), 2))
        if k % 3 == 0:
            pts = np.vstack([pts, pts[:2], 0.5 * (pts[0] + pts[1])])  # twins and a point on a segment
        if k % 5 == 0:
            pts = np.round(pts, 1)  # on a coarse grid: many collinear triples and ties in angle
            if len(np.unique(pts, axis=0)) < 3 or np.linalg.matrix_rank(pts - pts[0]) < 2:
                continue
        # When hulled by the patent's Graham scan and by Qhull
        mine, ref = graham_hull(pts), convex_hull_2d(pts)
        # Then the same vertex set, counter-clockwise and strictly convex
        assert sorted(map(tuple, mine)) == sorted(map(tuple, ref))
        assert strictly_convex_ccw(mine)


def test_separating_axes_agree_with_clipping():
    # Given pairs of random convex polygons at random distances
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(2000):
        a = random_convex(rng, np.zeros(2), 1.0)
        b = random_convex(rng, rng.uniform(-2.2, 2.2, 2), rng.uniform(0.2, 1.2))
        # Then the exact test says "overlap" exactly when the clipped intersection has area
        area = clip_area(a, b)
        assert polygons_overlap(a, b) == (area > 1e-12), area
        assert polygons_overlap(b, a) == polygons_overlap(a, b)
        hits += area > 1e-12
    assert 300 < hits < 1700  # both outcomes well represented


def test_touching_polygons_do_not_overlap_and_gap_is_kept():
    # Given two unit squares sharing an edge, and the same squares 0.1 apart
    a = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    assert not polygons_overlap(a, a + [1.0, 0.0])
    assert polygons_overlap(a, a + [0.999, 0.3])
    # Then a clearance of 0.2 calls 0.1 apart an overlap, a clearance of 0.05 does not
    assert polygons_overlap(a, a + [1.1, 0.0], gap=0.2)
    assert not polygons_overlap(a, a + [1.1, 0.0], gap=0.05)


# ---------------------------------------------------------------------------------------
# placement
# ---------------------------------------------------------------------------------------
def test_placement_is_exact_per_class_reproducible_and_disjoint():
    # Given the AC-13 targets on a 60 x 40 mm rectangle
    spec = Specimen("rectangle", 0.06, 0.04)
    tg = ac13_targets(spec)
    lo, hi = AC13_SIEVES[:-1] / 2, AC13_SIEVES[1:] / 2
    tg[hi * 2 > 0.0132] = 0.0  # no 13.2+ mm stones in a 40 mm strip
    # When placed twice with the same seed
    a = place_polygons(np.random.default_rng(11), spec, lo, hi, tg)
    b = place_polygons(np.random.default_rng(11), spec, lo, hi, tg)
    # Then identical results, every class on its area, polygons inside, convex and disjoint
    assert a.complete and np.array_equal(a.vertices, b.vertices) and np.array_equal(a.tries, b.tries)
    for c in np.flatnonzero(tg > 0):
        got = sum(polygon_area(a.polygon(p)) for p in np.flatnonzero(a.pclass == c))
        assert got == pytest.approx(tg[c], rel=1e-9)
    assert np.all(np.abs(a.vertices[:, 0]) <= 0.03) and np.all(np.abs(a.vertices[:, 1]) <= 0.02)
    assert all(strictly_convex_ccw(p) for p in a.polygons())
    assert _overlapping_pairs(a.polygons()) == []
    # and no polygon spans more than its class's upper size (its polar radii are <= d_upper / 2)
    for p in range(len(a)):
        poly = a.polygon(p)
        span = np.max(np.linalg.norm(poly[:, None] - poly[None], axis=-1))
        assert span <= 2 * hi[a.pclass[p]] * (1 + 1e-9)


def test_exact_test_reaches_where_bounding_circles_give_up():
    # Given AC-13 shares at 50 % aggregate in a 100 mm circle, a budget of 20 000 tries per polygon
    spec = Specimen("circle", 0.05)
    tg = ac13_targets(spec, fraction=0.50)
    lo, hi = AC13_SIEVES[:-1] / 2, AC13_SIEVES[1:] / 2
    exact = place_polygons(np.random.default_rng(2), spec, lo, hi, tg, test="exact", max_tries=20000)
    circle = place_polygons(np.random.default_rng(2), spec, lo, hi, tg, test="bounding_circle", max_tries=20000)
    # Then the exact test places everything, the conservative test stops short
    assert exact.complete and exact.placed.sum() == pytest.approx(tg.sum(), rel=1e-9)
    assert not circle.complete and circle.placed.sum() < 0.9 * tg.sum()
    # and what the circle test placed has disjoint bounding circles (it is conservative)
    cen = np.array([p.mean(axis=0) for p in circle.polygons()])
    assert _overlapping_pairs(circle.polygons()) == []
    assert len(cen) > 10


def test_a_class_smaller_than_one_polygon_is_met_by_scaling_out_of_class():
    # Given a class whose whole target is a tenth of one in-class polygon
    spec = Specimen("circle", 0.02)
    lo, hi = np.array([0.002]), np.array([0.003])
    tg = np.array([0.1 * 2.8 * 0.0025 ** 2])
    pl = place_polygons(np.random.default_rng(0), spec, lo, hi, tg)
    # Then the area is met with one polygon, reported as out of its class
    assert pl.complete and len(pl) == 1 and pl.out_of_class[0] == 1
    assert pl.placed[0] == pytest.approx(tg[0], rel=1e-9)


def _overlapping_pairs(polys):
    """Pairs whose clipped intersection has area (naive O(n^2) with a bounding-box cut)."""
    box = np.array([[p[:, 0].min(), p[:, 0].max(), p[:, 1].min(), p[:, 1].max()] for p in polys])
    bad = []
    for i in range(len(polys)):
        cand = np.flatnonzero((box[i + 1:, 0] < box[i, 1]) & (box[i + 1:, 1] > box[i, 0])
                              & (box[i + 1:, 2] < box[i, 3]) & (box[i + 1:, 3] > box[i, 2])) + i + 1
        for j in cand:
            if clip_area(polys[i], polys[j]) > 1e-18:  # m^2: 1e-6 mm^2
                bad.append((i, j))
    return bad


# ---------------------------------------------------------------------------------------
# the stage on the seed's worked example
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ac13(tmp_path_factory):
    out = tmp_path_factory.mktemp("ac13")
    run_case(CASES / "marshall_ac13_2d.yaml", out=out, quiet=True)
    return out


def test_ac13_section_classes_within_one_percent_disjoint_and_convex(ac13):
    # Given the patent's Marshall section (AC-13, r = 50 mm) after the polygons stage
    st = read_state(ac13 / "01-aggregates.h5")
    pg, g = st.groups["polygons"], st.groups["gradation"]
    start, v = pg["vertex_start"], pg["vertices"]
    polys = [v[start[p]:start[p + 1]] for p in range(len(start) - 1)]
    # Then every class's polygon area (recomputed from the vertices) is within 1 % of S m n_t
    for c, target in enumerate(g["class_amount"]):
        got = sum(polygon_area(polys[p]) for p in np.flatnonzero(pg["class"] == c))
        assert got == pytest.approx(target, rel=0.01, abs=1e-12), (c, got, target)
    # and the section holds 62.95 % aggregate >= 1.18 mm, every polygon strictly convex, inside the circle
    assert sum(map(polygon_area, polys)) / (math.pi * 0.05 ** 2) == pytest.approx(0.629546, rel=1e-5)
    assert all(strictly_convex_ccw(p) for p in polys)
    assert np.all(np.hypot(v[:, 0], v[:, 1]) <= 0.05 * (1 + 1e-12))
    assert all(3 <= len(p) <= 10 for p in polys)
    # and no two polygons overlap (clipping reference, all pairs with overlapping boxes)
    assert _overlapping_pairs(polys) == []
    # and the records say the same, with sieve sizes (square holes) mostly inside the class
    rec = st.groups["records/classes"]
    used = rec["count"] > 0
    assert np.all(np.abs(rec["error"][used]) < 1.0)
    assert np.all(rec["sieve_in_class"][used] >= 90.0)


def test_ac13_polygons_vtu_has_every_polygon(ac13):
    import meshio

    # Given the polygons stage's VTU
    mesh = meshio.read(ac13 / "aggregates" / "polygons.vtu")
    st = read_state(ac13 / "01-aggregates.h5")
    n_p = len(st["polygons/class"])
    # Then one polygon cell per polygon with its class, in the plane z = 0
    ids = np.concatenate(mesh.cell_data["polygon"])
    assert sorted(ids.tolist()) == list(range(n_p))
    cls = np.concatenate(mesh.cell_data["class"])
    assert np.array_equal(cls[np.argsort(ids)], st["polygons/class"])
    assert np.all(mesh.points[:, 2] == 0.0)
    assert (ac13 / "aggregates" / "specimen.vtu").exists()


SMALL = """\
name: s
dimension: 2
stages:
  - name: grading
    type: gradation
    sieves:  [1.18 mm, 2.36 mm, 4.75 mm]
    passing: [30, 60, 100]
    specimen: {shape: circle, radius: 10 mm}
    volumetrics: {kind: asphalt, asphalt_content: 0.05, aggregate_density: 2640 kg/m^3,
                  binder_density: 1100 kg/m^3, air_voids: 0.04, min_size: 1.18 mm}
  - name: aggregates
    type: polygons
    specimen: {shape: circle, radius: 10 mm}
    vertices: {min: 6, max: 10}
"""


@pytest.mark.parametrize("old, new, needles", [
    ("vertices: {min: 6, max: 10}", "vertices: {min: 8, max: 6}", ["vertices.max", "must be >="]),
    ("vertices: {min: 6, max: 10}", "vertices: {min: 2, max: 6}", ["vertices.min", ">= 3"]),
    ("vertices: {min: 6, max: 10}", "vertices: {min: 6, max: 10}\n    test: circles",
     ["test", "bounding_circle"]),
    ("    vertices: {min: 6, max: 10}", "    vertices: {min: 6, max: 10}\n    angle_fluctuation: 1.2",
     ["angle_fluctuation"]),
])
def test_bad_polygon_settings_are_rejected(tmp_path, old, new, needles):
    # Given a valid case with one defect in the polygons stage
    p = tmp_path / "s.yaml"
    p.write_text(SMALL.replace(old, new, 1))
    # When checked: exit code 2, the key named, no traceback
    result = CliRunner().invoke(cli, ["check", str(p)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


def test_specimen_mismatch_and_3d_cases_are_refused(tmp_path):
    # Given the polygons stage told of another specimen than the gradation stage
    p = tmp_path / "s.yaml"
    p.write_text(SMALL.replace("specimen: {shape: circle, radius: 10 mm}\n    vertices",
                               "specimen: {shape: circle, radius: 12 mm}\n    vertices"))
    result = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "run"), "--quiet"])
    assert result.exit_code == 2 and "same specimen" in result.output, result.output
    # and a 3D case
    p.write_text(SMALL.replace("dimension: 2", "dimension: 3").replace(
        "specimen: {shape: circle, radius: 10 mm}\n    volumetrics", "specimen: {shape: cylinder, diameter: 20 mm, "
        "height: 10 mm}\n    volumetrics"))
    result = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "run3"), "--quiet"])
    assert result.exit_code == 2 and "dimension: 2" in result.output, result.output


def test_bounding_circle_stage_stops_with_a_clear_message(tmp_path):
    # Given a dense mix (60 % of the section) placed with the conservative test and a small budget
    p = tmp_path / "s.yaml"
    p.write_text(SMALL + "    test: bounding_circle\n    max_tries: 2000\n")
    result = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "run"), "--quiet"])
    # Then exit 1, saying how far it got and what to change, with the partial placement kept
    assert result.exit_code == 1, result.output
    assert "failed placements in a row" in result.output and "try test: exact" in result.output
    assert (tmp_path / "run" / "aggregates" / "polygons.vtu").exists()


def test_docs_list_the_registered_section_fields():
    from demcli.stages.base import load_stage_types
    from demcli.state.fields import schema_markdown

    load_stage_types()  # the stage modules register their groups at import
    # Given the rows of the groups the 2D section stages register
    rows = [ln for ln in schema_markdown(["polygons", "section"]).splitlines() if ln.startswith("| polygons")
            or ln.startswith("| section")]
    # Then docs/polygons.md shows each of them verbatim
    text = (CASES.parent / "docs" / "polygons.md").read_text(encoding="utf-8")
    missing = [r for r in rows if r not in text]
    assert rows and not missing, f"docs/polygons.md is out of date; first missing row: {missing[:1]}"
