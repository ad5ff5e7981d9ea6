"""Discretize stage (seed 001): hexagonal balls -> aggregate clumps, mastic balls, voids.

References written here: a point-in-convex-polygon test by triangle areas, and mass
properties of a disk union integrated on a pixel grid.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.geometry.section2d import Specimen, hex_lattice
from demcli.stages.asphalt.discretize import group_disk_properties
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"


def inside_by_areas(poly, pts):
    """Points strictly inside a convex polygon: the fan of triangles to p adds up to its area."""
    x, y = poly[:, 0], poly[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    tot = np.zeros(len(pts))
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        tot += 0.5 * np.abs((a[0] - pts[:, 0]) * (b[1] - pts[:, 1]) - (b[0] - pts[:, 0]) * (a[1] - pts[:, 1]))
    return tot <= area * (1 + 1e-9)


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    out = tmp_path_factory.mktemp("smoke2d")
    run_case(CASES / "smoke" / "marshall_2d.yaml", out=out, quiet=True)
    return out


def test_disk_union_properties_match_a_pixel_integration():
    # Given a few hex-packed disks (r = 1, spacing 2: touching, not overlapping) in an L shape
    r = 1.0
    lat = hex_lattice(Specimen("rectangle", 12.0, 12.0), r)
    pick = (lat.centres[:, 0] > -3.5) & (lat.centres[:, 0] < 2.5) & (lat.centres[:, 1] > -2) & (
        (lat.centres[:, 1] < 0.5) | (lat.centres[:, 0] < -1.5)) & (lat.centres[:, 1] < 4)
    c = lat.centres[pick]
    assert 6 <= len(c) <= 30
    # When their mass properties are summed exactly and integrated on a fine pixel grid
    cnt, mass, com, mom, ang, off = group_disk_properties(np.zeros(len(c), np.int64), c, r, 2.0, 1)
    h = 0.01
    gx, gy = np.meshgrid(np.arange(-6, 6, h) + h / 2, np.arange(-6, 6, h) + h / 2)
    inside = np.zeros(gx.shape, bool)
    for p in c:
        inside |= (gx - p[0]) ** 2 + (gy - p[1]) ** 2 <= r * r
    w = 2.0 * h * h
    m_ref = w * inside.sum()
    cx, cy = (gx[inside].sum() * w / m_ref, gy[inside].sum() * w / m_ref)
    dx, dy = gx[inside] - cx, gy[inside] - cy
    ixx, iyy, ixy = w * (dy ** 2).sum(), w * (dx ** 2).sum(), -w * (dx * dy).sum()
    ref = np.linalg.eigvalsh([[ixx, ixy], [ixy, iyy]])
    # Then they agree to the pixel resolution
    assert mass[0] == pytest.approx(m_ref, rel=2e-3)
    assert com[0] == pytest.approx([cx, cy], abs=5e-3)
    assert mom[0, :2] == pytest.approx(ref, rel=5e-3)
    assert mom[0, 2] == pytest.approx(ixx + iyy, rel=5e-3)
    # and the offsets are in the principal frame: no product of inertia there
    assert abs(np.sum(off[:, 0] * off[:, 1])) < 1e-9 * np.sum(off ** 2)


def test_section_balls_clumps_mastic_and_voids(smoke):
    # Given the smoke section (30 x 20 mm, r = 0.4 mm balls)
    st = read_state(smoke / "02-section.h5")
    pg, sec = st.groups["polygons"], st.groups["section"]
    r = float(sec["ball_radius"])
    names = list(st.groups["materials"]["name"])
    agg, mas = names.index("aggregate"), names.index("mastic")
    centres = st.sphere_centres()
    mat = st["spheres/material"]
    body = st["spheres/body"]
    # Then the world sphere centres sit on the hexagonal lattice (x + R(q) offset)
    lat = hex_lattice(Specimen("rectangle", 0.03, 0.02), r)
    key = {tuple(np.round(p / r, 6)) for p in lat.centres}
    assert all(tuple(np.round(p / r, 6)) in key for p in centres[:, :2])
    assert np.all(centres[:, 2] == 0.0)
    # and every lattice ball is a sphere or a void, each once
    voids = sec["void_centres"]
    assert len(centres) + len(voids) == len(lat.centres)
    # and a ball is aggregate exactly when its centre lies inside a polygon, in that polygon's clump
    start, v = pg["vertex_start"], pg["vertices"]
    owner = np.full(len(centres), -1)
    for p in range(len(start) - 1):
        owner[inside_by_areas(v[start[p]:start[p + 1]], centres[:, :2])] = p
    assert np.array_equal(owner >= 0, mat == agg)
    bp = sec["body_polygon"]
    assert np.array_equal(bp[body], owner)
    # and deleted balls were mastic (outside every polygon), their area within one ball of S VV
    for p in range(len(start) - 1):
        assert not inside_by_areas(v[start[p]:start[p + 1]], voids).any()
    cell = 2 * math.sqrt(3) * r * r
    s_vv = float(st["gradation/totals"][2])
    assert abs(len(voids) * cell - s_vv) <= 0.5 * cell
    assert sec["areas"][4] == pytest.approx(len(voids) * cell) and sec["areas"][5] == s_vv
    # and mastic balls are single-ball bodies with m = rho t pi r^2, I = m r^2 / 2
    nb = len(st["bodies/mass"])
    counts = np.bincount(body, minlength=nb)
    single_mastic = np.unique(body[mat == mas])
    assert np.all(counts[single_mastic] == 1)
    m_mas = 1800 * 1e-3 * math.pi * r * r
    assert np.allclose(st["bodies/mass"][single_mastic], m_mas, rtol=1e-12)
    assert np.allclose(st["bodies/inertia"][single_mastic], 0.5 * m_mas * r * r, rtol=1e-12)


def test_clump_bodies_have_exact_principal_mass_properties(smoke):
    # Given the smoke section's aggregate clumps
    st = read_state(smoke / "02-section.h5")
    r = float(st["section/ball_radius"])
    body, off = st["spheres/body"], st["spheres/offset"]
    m1 = 2640 * 1e-3 * math.pi * r * r
    for b in np.unique(body[st["section/body_polygon"][body] >= 0]):
        mine = body == b
        n = int(mine.sum())
        d = off[mine]
        # Then mass = n m1, the centre of mass is the members' mean (zero mean offset)
        assert st["bodies/mass"][b] == pytest.approx(n * m1, rel=1e-12)
        assert np.allclose(d.mean(axis=0), 0.0, atol=1e-15)
        if n == 1:
            continue
        # and I_zz = sum m1 (r^2/2 + |d|^2) = I_1 + I_2, with no product of inertia in the body frame
        i1, i2, izz = st["bodies/inertia"][b]
        assert izz == pytest.approx(m1 * (n * r * r / 2 + np.sum(d[:, :2] ** 2)), rel=1e-12)
        assert i1 + i2 == pytest.approx(izz, rel=1e-12) and i1 <= i2 * (1 + 1e-12)
        assert abs(np.sum(d[:, 0] * d[:, 1])) <= 1e-9 * np.sum(d ** 2)
        # and the orientation is a turn about z
        q = st["bodies/q"][b]
        assert q[1] == 0 and q[2] == 0 and np.linalg.norm(q) == pytest.approx(1.0)


def test_engine_planar_clumps_rest_and_spin_rigidly(smoke):
    from demcli.engine.materials import ContactModel, Material
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System, Walls

    st = read_state(smoke / "02-section.h5")
    mats = [Material(n, float(d)) for n, d in zip(st["materials/name"], st["materials/density"])]
    model = ContactModel(law="linear", kn=1e5)
    plan = make_plan(["planar"], clumps=True)
    groups = {"bodies": dict(st.groups["bodies"]), "spheres": dict(st.groups["spheres"])}
    # Given the whole section at rest, no gravity: hex-packed balls touch but do not overlap
    sys_ = System(groups, mats, model, plan, Walls(), Dynamics(gravity=(0.0, 0.0, 0.0)), dt=1.0)
    sys_.dt = 0.2 * sys_.critical_dt()
    status, _ = sys_.advance(200)
    # Then nothing moves
    assert status == 0 and float(np.abs(sys_.v).max()) < 1e-9 and float(np.abs(sys_.w).max()) < 1e-6
    # Given the largest clump alone, spun about z at 100 rad/s
    body = st["spheres/body"]
    b = int(np.argmax(np.bincount(body)))
    mine = body == b
    one = {"bodies": {k: np.asarray(a)[b:b + 1].copy() for k, a in st.groups["bodies"].items()},
           "spheres": {k: np.asarray(a)[mine].copy() for k, a in st.groups["spheres"].items()}}
    one["spheres"]["body"][:] = 0
    one["bodies"]["omega"][0] = [0.0, 0.0, 100.0]
    solo = System(one, mats, model, plan, Walls(), Dynamics(gravity=(0.0, 0.0, 0.0)), dt=1e-5)
    izz = one["bodies"]["inertia"][0, 2]
    before = solo.xs.copy()
    status, _ = solo.advance(1000)  # 0.01 s: one radian
    # Then it turned one radian about its centre of mass, rigidly, in the plane, at constant spin
    assert status == 0 and solo.w[0] == pytest.approx([0.0, 0.0, 100.0], rel=1e-12, abs=1e-12)
    assert solo.L[0, 2] == pytest.approx(izz * 100.0, rel=1e-12)
    c, s = math.cos(1.0), math.sin(1.0)
    rel = before - solo.x[0]
    turned = np.stack([c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1], rel[:, 2]], axis=1)
    assert np.allclose(solo.xs - solo.x[0], turned, atol=1e-12)
    assert np.all(solo.xs[:, 2] == 0.0)


def test_section_vtu_tells_phases_apart(smoke):
    import meshio

    # Given the section's sphere snapshot and its polygons
    mesh = meshio.read(smoke / "section" / "spheres_000000.vtu")
    st = read_state(smoke / "02-section.h5")
    # Then every sphere carries its material (aggregate / mastic) and body id, clumps share ids
    assert sorted(set(mesh.point_data["material"].tolist())) == [0, 1]
    assert len(mesh.points) == len(st["spheres/radius"])
    agg_ids = mesh.point_data["body_id"][mesh.point_data["material"] == 0]
    assert len(np.unique(agg_ids)) == int((st["section/body_polygon"] >= 0).sum()) < len(agg_ids)
    poly = meshio.read(smoke / "section" / "polygons.vtu")
    assert sum(len(c.data) for c in poly.cells) == len(st["polygons/class"])
    assert (smoke / "section" / "spheres.pvd").exists()


CASE = (CASES / "smoke" / "marshall_2d.yaml").read_text()


@pytest.mark.parametrize("old, new, needles", [
    ("mastic: {material: mastic}", "mastic: {material: mastik}", ["mastic.material", "unknown material"]),
    ("mastic: {material: mastic}", "mastic: {material: aggregate}", ["mastic.material", "must differ"]),
    ("ball_radius: 0.4 mm", "ball_radius: -0.4 mm", ["ball_radius", "> 0"]),
    ("aggregate: {material: aggregate}", "aggregate: {material: aggregate, membership: half}",
     ["membership", "centre"]),
])
def test_bad_discretize_settings_are_rejected(tmp_path, old, new, needles):
    # Given the smoke case with one defect in the discretize stage
    assert old in CASE
    p = tmp_path / "c.yaml"
    p.write_text(CASE.replace(old, new, 1))
    # When checked: exit code 2, the key and rule named, no traceback
    result = CliRunner().invoke(cli, ["check", str(p)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


def test_too_few_mastic_balls_for_the_voids_is_a_clear_error(tmp_path):
    # Given 45 % air voids, all aggregate as particles and coarse 1.2 mm balls (the lattice misses
    # much of the boundary strip): the voids need more balls than the mastic has
    p = tmp_path / "c.yaml"
    p.write_text(CASE.replace("air_voids: 0.04", "air_voids: 0.45").replace("passing: [26.4, ", "passing: [0, ")
                 .replace("ball_radius: 0.4 mm", "ball_radius: 1.2 mm"))
    result = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "run"), "--quiet"])
    # Then the run stops (exit 1) saying why
    assert result.exit_code == 1, result.output
    assert "only" in result.output and "are mastic" in result.output
