"""``demcli sieve``: sieve sizes of meshes, vertex tables and state files, passing curves, bad input.

Expected values are worked by hand. The least shadow of an a x b x c box (a <= b <= c) is its
a x b face (along the c axis), so the projection sieve size is the square aperture of that
rectangle, min(b, (a + b)/sqrt 2) (demcli.geometry.square_aperture): 10 mm for a 10 mm cube,
20 mm for 10 x 20 x 30 mm, (4 + 20)/sqrt 2 = 16.97 mm for a 4 x 20 x 30 mm plate, which
passes turned on its diagonal. Tolerances: 1e-9 relative on sizes, volumes and percents
(exact geometry, round-off only), 1e-12 absolute on percents that are sums of masses.
"""

import csv
import itertools
import math

import meshio
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial import ConvexHull

from demcli.cli import SIEVE_METHODS, cli

REL = 1e-9
PLATE = (4 + 20) / math.sqrt(2)  # mm, the 4 x 20 x 30 plate on its diagonal


def _box(a, b, c, shift=(0.0, 0.0, 0.0)):
    """Corners (8, 3) and hull triangles of an a x b x c box."""
    p = np.array(list(itertools.product([0, a], [0, b], [0, c])), float) + shift
    return p, ConvexHull(p).simplices


def _mesh(path, boxes, **write_options):
    """One mesh file holding the boxes as separate parts; returns the path."""
    pts, tris = [], []
    for k, (points, simplices) in enumerate(boxes):
        tris.append(simplices + 8 * k)
        pts.append(points)
    meshio.Mesh(np.concatenate(pts), [("triangle", np.concatenate(tris))]).write(path, **write_options)
    return path


@pytest.fixture
def three_boxes(tmp_path):
    """cube 10, box 10 x 20 x 30 and plate 4 x 20 x 30 (mm) as the three parts of one OBJ."""
    return _mesh(tmp_path / "three.obj", [_box(10, 10, 10), _box(10, 20, 30, (50, 0, 0)),
                                          _box(4, 20, 30, (100, 0, 0))])


def _invoke(*args):
    return CliRunner().invoke(cli, ["sieve", *map(str, args)])


def _read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _column(rows, name):
    return np.array([float(r[name]) for r in rows])


def test_method_choices_are_the_toolkits():
    from demcli.geometry.projection import METHODS

    assert SIEVE_METHODS == METHODS


def test_boxes_of_an_obj_mesh_get_their_square_apertures_and_shape_indices(tmp_path, three_boxes):
    # Given three boxes in one OBJ file, in mm
    result = _invoke(three_boxes, "--unit", "mm", "--out", tmp_path / "out")
    # Then each connected part is one particle, sized by its least shadow's rectangle
    assert result.exit_code == 0, result.output
    assert "3 particles from 1 file (3 polyhedra); sieve size by projection, passing by volume" in result.output
    rows = _read(tmp_path / "out" / "particles.csv")
    assert [r["particle"] for r in rows] == ["0", "1", "2"] and {r["kind"] for r in rows} == {"polyhedron"}
    assert np.allclose(_column(rows, "sieve_size[mm]"), [10, 20, PLATE], rtol=REL)
    assert np.allclose(_column(rows, "volume[m^3]"), [1e-6, 6e-6, 2.4e-6], rtol=REL)
    assert np.allclose(_column(rows, "shadow_length[mm]"), [10, 20, 20], rtol=REL)
    assert np.allclose(_column(rows, "shadow_width[mm]"), [10, 10, 4], rtol=REL)
    assert np.allclose(_column(rows, "short[mm]"), [10, 10, 4], rtol=REL)
    assert np.allclose(_column(rows, "elongation"), [1, 2 / 3, 2 / 3], rtol=REL)
    # flaky: short side < 0.6 x the particle's own sieve size (10 < 12; 4 < 10.2)
    assert [r["flaky"] for r in rows] == ["0", "1", "1"] and [r["elongated"] for r in rows] == ["0"] * 3
    assert "mass[kg]" not in rows[0]  # no density: no masses
    assert not (tmp_path / "out" / "passing.csv").exists()


@pytest.mark.parametrize("method, expected", [
    ("volume_sphere", [10 * (6 / math.pi) ** (1 / 3), (6 * 6000 / math.pi) ** (1 / 3)]),
    ("volume_cube", [10, 6000 ** (1 / 3)]),
    ("inertia_square", [10, 20]),  # across the long axis the box shows its 10 x 20 face: 20 wide
])
def test_other_methods_on_binary_stl(tmp_path, method, expected):
    # Given a cube and a box in a binary STL file, in mm
    path = tmp_path / "two.stl"
    _mesh(path, [_box(10, 10, 10), _box(10, 20, 30, (40, 0, 0))], binary=True)
    result = _invoke(path, "--unit", "mm", "--method", method, "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert np.allclose(_column(_read(tmp_path / "particles.csv"), "sieve_size[mm]"), expected, rtol=REL)


def test_passing_by_mass_class_shares_and_target(tmp_path, three_boxes):
    # Given the three boxes (1000, 6000 and 2400 mm^3) at 2650 kg/m^3 and sieves 12.5, 18, 25 mm
    out = tmp_path / "out"
    result = _invoke(three_boxes, "--unit", "mm", "--density", "2.65 g/cm3", "--sieves", "12.5mm,18 mm,0.025",
                     "--target", "5,40,100", "--out", out)
    assert result.exit_code == 0, result.output
    # Then passing is by mass: 1000 / 9400 through 12.5 mm, + 2400 (the plate, 16.97 mm) through 18 mm
    assert "passing by mass" in result.output
    rows = _read(out / "particles.csv")
    assert np.allclose(_column(rows, "mass[kg]"), [2.65e-3, 15.9e-3, 6.36e-3], rtol=REL)
    passing = _read(out / "passing.csv")
    assert _column(passing, "sieve[mm]").tolist() == [12.5, 18, 25]
    expected = [100 * 1000 / 9400, 100 * 3400 / 9400, 100]
    assert np.allclose(_column(passing, "passing[%]"), expected, rtol=REL, atol=1e-12)
    assert _column(passing, "target[%]").tolist() == [5, 40, 100]
    # And the class shares are compared with the target's
    classes = _read(out / "classes.csv")
    assert _column(classes, "upper[mm]")[-1] == np.inf
    share = np.diff([0, *expected, 100])
    assert np.allclose(_column(classes, "share[%]"), share, rtol=REL, atol=1e-12)
    assert np.allclose(_column(classes, "target[%]"), [5, 35, 60, 0])
    assert np.allclose(_column(classes, "difference[%]"), share - [5, 35, 60, 0], rtol=REL, atol=1e-12)
    assert "difference[%]" in result.output and (out / "passing.png").stat().st_size > 0


def _materials():
    return {"name": np.array(["rock"], dtype=object), "density": np.array([2500.0]),
            **{k: np.ones(1) for k in ("young", "poisson", "friction", "rolling_friction", "restitution")}}


def _sphere_state(path):
    """Spheres of radius 5, 8 and 12 mm, a clump of two touching 5 mm balls and one of a 5 mm and
    a 3 mm ball, density 2500; then a loading plate (an actor), which is not a particle."""
    from demcli.engine.actors import add_actor
    from demcli.geometry import convex_hull
    from demcli.state import new_state, write_state

    radius = np.array([5.0, 8.0, 12.0, 5.0, 5.0, 5.0, 3.0]) * 1e-3
    body = np.array([0, 1, 2, 3, 3, 4, 4])
    offset = np.zeros((7, 3))
    offset[3:5, 0] = [-5e-3, 5e-3]
    offset[5:, 1] = [-4e-3, 4e-3]
    mass = 2500 * 4 / 3 * math.pi * np.array([5.0 ** 3, 8 ** 3, 12 ** 3, 2 * 5 ** 3, 5 ** 3 + 3 ** 3]) * 1e-9
    n = 5
    groups = {"bodies": {"x": np.arange(3 * n, dtype=float).reshape(n, 3) * 0.05, "v": np.zeros((n, 3)),
                         "q": np.tile([1.0, 0, 0, 0], (n, 1)), "omega": np.zeros((n, 3)), "mass": mass,
                         "inertia": np.ones((n, 3)) * 1e-9, "id": np.arange(n), "flags": np.zeros(n, np.int8)},
              "spheres": {"body": body, "offset": offset, "radius": radius, "material": np.zeros(7, np.int64)},
              "materials": _materials()}
    groups = add_actor(groups, convex_hull(_box(0.3, 0.3, 0.02)[0]), [0.1, 0.1, 0.5], 7800.0, 0, "plate")
    st = new_state("deposit", "dem")
    st.groups.update(groups)
    return write_state(path, st), mass


def test_spheres_and_a_clump_of_a_state_file(tmp_path):
    # Given a state of three spheres, two clumps of two balls in a row and a loading plate
    path, mass = _sphere_state(tmp_path / "spheres.h5")
    result = _invoke(path, "--sieves", "11mm,20mm", "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    # Then the plate is left out, a sphere's size is its diameter and a clump's that of its end view,
    # the larger ball's disk: exact for equal balls, 0.6 % low for sampled ball surfaces (checked to 1 %)
    assert "5 particles from 1 file (3 spheres, 2 clumps)" in result.output
    rows = _read(tmp_path / "out" / "particles.csv")
    assert [r["kind"] for r in rows] == ["sphere"] * 3 + ["clump"] * 2
    sizes = _column(rows, "sieve_size[mm]")
    assert np.allclose(sizes[:4], [10, 16, 24, 10], rtol=REL) and sizes[4] == pytest.approx(10, rel=0.01)
    assert np.allclose(_column(rows, "mass[kg]"), mass, rtol=REL)
    assert np.allclose(_column(rows, "volume[m^3]"), mass / 2500, rtol=REL)
    # And passing is by the bodies' masses, in units of 4/3 pi rho mm^3: 125 + 250 + 152 of 2767 through 11 mm
    total = 125 + 512 + 1728 + 250 + 152
    expected = [100 * 527 / total, 100 * 1039 / total]
    assert np.allclose(_column(_read(tmp_path / "out" / "passing.csv"), "passing[%]"), expected, rtol=REL)


def test_polyhedra_of_a_state_file_sized_whatever_their_rotation(tmp_path):
    # Given the cube, the box and the plate (in m) as turned polyhedral bodies of a state
    from demcli.engine.poly_shape import polyhedra_groups
    from demcli.geometry import convex_hull
    from demcli.state import new_state, write_state

    polys = [convex_hull(_box(*dims)[0] * 1e-3) for dims in [(10, 10, 10), (10, 20, 30), (4, 20, 30)]]
    q = np.array([[1, 0, 0, 0], [0.9, 0.3, -0.2, 0.1], [0.5, 0.5, 0.5, 0.5]])
    st = new_state("assemble", "assemble")
    st.groups.update(polyhedra_groups(polys, 2000.0, q=q), materials=_materials())
    result = _invoke(write_state(tmp_path / "poly.h5", st), "--out", tmp_path)
    # Then they get the sizes of the boxes of the mesh, and their masses from the state
    assert result.exit_code == 0, result.output
    rows = _read(tmp_path / "particles.csv")
    assert np.allclose(_column(rows, "sieve_size[mm]"), [10, 20, PLATE], rtol=REL)
    assert np.allclose(_column(rows, "mass[kg]"), 2000 * np.array([1e-6, 6e-6, 2.4e-6]), rtol=REL)


def test_csv_of_2d_polygons_passes_by_area(tmp_path):
    # Given a 10 x 10 square and a 10 x 20 rectangle as 2D vertex rows, in mm
    path = tmp_path / "outline.csv"
    path.write_text("particle,x,y\n# corners in mm\n"
                    + "".join(f"sq,{x},{y}\n" for x, y in [(0, 0), (10, 0), (10, 10), (0, 10)])
                    + "".join(f"rect,{x},{y}\n" for x, y in [(0, 0), (10, 0), (10, 20), (0, 20), (5, 5)]))
    result = _invoke(path, "--unit", "mm", "--sieves", "15mm", "--out", tmp_path / "out")
    # Then each outline is sized as the polygon it spans (min(20, 30/sqrt 2) = 20 mm), weighed by area
    assert result.exit_code == 0, result.output
    assert "2 polygons" in result.output and "passing by area" in result.output
    rows = _read(tmp_path / "out" / "particles.csv")
    assert [r["particle"] for r in rows] == ["sq", "rect"]
    assert np.allclose(_column(rows, "sieve_size[mm]"), [10, 20], rtol=REL)
    assert np.allclose(_column(rows, "area[m^2]"), [1e-4, 2e-4], rtol=REL)
    assert np.allclose(_column(_read(tmp_path / "out" / "passing.csv"), "passing[%]"), [100 / 3], rtol=REL)


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name, text, args, needles", [
    ("state.h5", "not a state\n", [], ["state.h5", "not an HDF5 state file"]),
    ("shape.xyz", "1 2 3\n", [], ["shape.xyz", "unknown file type .xyz"]),
    ("pts.csv", "id,x,y,z\n", [], ["pts.csv", "the header is id,x,y,z", "particle,x,y,z"]),
    ("pts.csv", "particle,x,y,z\na,0,0,0\na,1,0,zero\n", [], ["pts.csv", "line 3", "not a number"]),
    ("flat.csv", "particle,x,y,z\nf,0,0,0\nf,1,0,0\nf,0,1,0\nf,1,1,0\n", [], ["flat.csv", "particle f", "coplanar"]),
    ("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", [], ["bad.obj", "refers to vertex 7"]),
    ("bad.stl", "solid x\n garbage\n", [], ["bad.stl", "cannot read the mesh"]),
    ("ok.csv", "particle,x,y\np,0,0\np,1,0\np,0,1\n", ["--method", "inertia_square"], ["ok.csv", "polygons"]),
    ("ok.csv", "particle,x,y\np,0,0\np,1,0\np,0,1\n", ["--sieves", "25mm,16mm"], ["--sieves", "ascending"]),
    ("ok.csv", "particle,x,y\np,0,0\np,1,0\np,0,1\n", ["--sieves", "16 kg"], ["--sieves", "not a length"]),
    ("ok.csv", "particle,x,y\np,0,0\np,1,0\np,0,1\n", ["--target", "50"], ["--target needs --sieves"]),
    ("ok.csv", "particle,x,y\np,0,0\np,1,0\np,0,1\n", ["--sieves", "1mm,2mm", "--target", "50"],
     ["--target", "one value per sieve"]),
])
def test_bad_input_is_one_line_naming_the_file_and_exit_2(tmp_path, name, text, args, needles):
    result = _invoke(_write(tmp_path, name, text), *args, "--out", tmp_path / "out")
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and result.output.startswith("Error: ")
    assert len(result.output.strip().splitlines()) == 1, result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


def test_polygons_of_a_2d_section_state(tmp_path):
    # Given a 2D section state holding a 10 x 10 mm square and a 4 x 20 mm strip
    from demcli.state import new_state, write_state

    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]]) * 1e-3
    strip = np.array([[20, 0], [24, 0], [24, 20], [20, 20]]) * 1e-3
    st = new_state("polygons", "polygons", dim=2)
    st.groups.update(
        bodies={"x": np.zeros((0, 3)), "v": np.zeros((0, 3)), "q": np.zeros((0, 4)), "omega": np.zeros((0, 3)),
                "mass": np.zeros(0), "inertia": np.zeros((0, 3)), "id": np.zeros(0, np.int64),
                "flags": np.zeros(0, np.int8)},
        spheres={"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)), "radius": np.zeros(0),
                 "material": np.zeros(0, np.int64)},
        materials=_materials(),
        polygons={"vertex_start": np.array([0, 4, 8]), "vertices": np.concatenate([square, strip]),
                  "class": np.zeros(2, np.int64), "area": np.array([1e-4, 8e-5]),
                  "centroid": np.array([[5e-3, 5e-3], [22e-3, 10e-3]]), "specimen_shape": np.int64(1),
                  "specimen_size": np.array([0.1, 0.1]), "class_target": np.array([2e-4]),
                  "class_placed": np.array([1.8e-4]), "class_tries": np.array([3])})
    result = _invoke(write_state(tmp_path / "section.h5", st), "--sieves", "12mm", "--out", tmp_path)
    # Then each polygon gets its square aperture: 10 mm and the strip turned, (4 + 20)/sqrt 2 mm
    assert result.exit_code == 0, result.output
    rows = _read(tmp_path / "particles.csv")
    assert np.allclose(_column(rows, "sieve_size[mm]"), [10, PLATE], rtol=REL)
    assert np.allclose(_column(_read(tmp_path / "passing.csv"), "passing[%]"), [100 * 100 / 180], rtol=REL)
