"""Virtual sieving of particles read from files: the work of ``demcli sieve``.

Every particle gets a sieve size, the side of the smallest square hole it passes (by a
method of :func:`demcli.geometry.sieve_size`), a volume (an area in 2D) and, where known,
a mass. Given sieves, the set gets its passing curve, its class shares (Shao et al. 2017,
:func:`demcli.geometry.class_shares`) and, given a target curve, their comparison
(:func:`demcli.geometry.compare_gradation`). Files by extension:

- ``.h5``: a demcli state: its polyhedra, its sphere bodies (one sphere: a sphere;
  several: a clump) or, in a 2D section, its aggregate polygons. Loading actors (plate,
  sleeper) are left out, and of a state with carved asphalt ``aggregates`` only those (not
  the mastic balls). Masses are the bodies'; the volume of a sphere body is its mass over
  the density of its spheres' material (a clump's balls overlap).
- ``.obj``, ``.stl``, ``.ply``, ``.off`` (read by meshio): each connected part is one
  particle, sized as the convex hull of its vertices (a file of points without cells:
  one particle).
- ``.csv``: a vertex table with the header ``particle,x,y,z`` (each particle the convex
  hull of its points) or ``particle,x,y`` (2D: polygons, likewise).

The 3D particles of meshes and CSV files get a mass only from a given density. Passing is
by mass when every particle has one, else by volume (by area in 2D): the same for one
density. Lengths are m inside, mm in the outputs. See docs/sieve.md.
"""

import csv
import io
import math
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from demcli.errors import InputError
from demcli.units import UnitError, to_si

MESH_FORMATS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off"}  # suffix -> meshio module
VOLUME_METHODS = ("volume_sphere", "volume_cube")

# particles.csv: (row key, header, factor from SI or None for text and flags); "volume" is an area in 2D
COLUMNS = (("file", "file", None), ("particle", "particle", None), ("kind", "kind", None),
           ("sieve_size", "sieve_size[mm]", 1e3), ("volume", "volume[m^3]", 1.0), ("mass", "mass[kg]", 1.0),
           ("shadow_length", "shadow_length[mm]", 1e3), ("shadow_width", "shadow_width[mm]", 1e3),
           ("length", "length[mm]", 1e3), ("intermediate", "intermediate[mm]", 1e3), ("short", "short[mm]", 1e3),
           ("elongation", "elongation", 1.0), ("flatness", "flatness", 1.0), ("flaky", "flaky", None),
           ("elongated", "elongated", None))
PLURAL = {"polyhedron": "polyhedra", "sphere": "spheres", "clump": "clumps", "polygon": "polygons"}


@dataclass(frozen=True, eq=False)
class SieveResult:
    """Sized particles and, with sieves, their gradation.

    ``rows``: one dict per particle with keys of :data:`COLUMNS` (SI units); ``dim``: 3, or 2
    for polygons; ``method``: the sieve-size method; ``weight``: what passing is a percent of
    (``mass``, ``volume`` or ``area``). With sieves: ``sieves`` (k,), m; ``passing`` (k,),
    percent; ``shares`` (k + 1,), percent by class; with a target also ``target`` (k,),
    percent passing, and ``comparison`` (a GradationComparison). ``files``: the paths written.
    """

    rows: list
    dim: int
    method: str
    weight: str
    sieves: np.ndarray | None = None
    passing: np.ndarray | None = None
    shares: np.ndarray | None = None
    target: np.ndarray | None = None
    comparison: object = None
    files: tuple = ()

    def summary(self):
        """A few lines for the terminal: what was sized, the size range, the passing and class
        tables (with the target), the files written."""
        sizes = 1e3 * np.array([r["sieve_size"] for r in self.rows])
        lines = [_headline(self), f"sieve size {sizes.min():.4g} to {sizes.max():.4g} mm, "
                                  f"median {np.median(sizes):.4g} mm"]
        if self.sieves is not None:
            passing, classes = _gradation_columns(self)
            lines += ["", *_aligned(passing), "", *_aligned(classes)]
        return "\n".join(lines + [f"wrote {p}" for p in self.files])


def sieve_files(paths, *, sieves=None, method="projection", density=None, target=None, unit="m", out="sieve"):
    """Size the particles of ``paths`` and, given sieves, sieve them; write the tables and the
    curve into the folder ``out``.

    sieves: ascending apertures as a comma list with units (``"16mm,25mm"``; a plain number is
    in m); method: one of ``demcli.geometry.projection.METHODS``; density: of mesh and CSV
    particles (``"2650kg/m3"``); target: percent passing at each sieve (``"0,40,100"``); unit:
    of mesh and CSV coordinates (``"mm"``). Returns a :class:`SieveResult`; bad options and
    files raise InputError (exit code 2) naming them.
    """
    apertures = _sieves(sieves) if sieves else None
    goal = _target(target, apertures) if target else None
    rho = _quantity(density, "kg/m^3", "--density") if density else None
    scale = _quantity(f"1 {unit}", "m", "--unit")
    dims, rows = set(), []
    for path in paths:
        dim, got = read_particles(path, method, scale, rho)
        dims.add(dim)
        rows += got
    if len(dims) > 1:
        raise InputError("cannot sieve 2D polygons and 3D particles together (areas against volumes)")
    result = _grade(rows, dims.pop(), method, apertures, goal)
    return replace(result, files=_write(result, Path(out)))


def read_particles(path, method="projection", scale=1.0, density=None):
    """Sized particles of one file (see the module docstring): (dim, rows), rows as dicts of
    :data:`COLUMNS` keys in SI units. scale: metres per coordinate unit of mesh and CSV files;
    density (kg/m^3): gives their 3D particles a mass."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".h5":
        dim, rows = _state_rows(path, method)
    elif suffix in MESH_FORMATS or suffix == ".csv":
        dim, parts = _csv_parts(path, scale) if suffix == ".csv" else (3, _mesh_parts(path, scale))
        rows = _part_rows(path, dim, parts, method, density)
    else:
        raise InputError(f"{path}: unknown file type {suffix or '(no extension)'}: give a state (.h5), a mesh "
                         f"({', '.join(MESH_FORMATS)}) or a vertex table (.csv)")
    if not rows:
        raise InputError(f"{path}: no particles to sieve")
    return dim, [dict(row, file=str(path)) for row in rows]


# ---------------------------------------------------------------------------------------
# options
# ---------------------------------------------------------------------------------------

def _quantity(text, unit, option):
    """A positive quantity written as in case files (``"16 mm"``), in the SI ``unit``."""
    try:
        value = to_si(text.strip(), unit)
    except UnitError as exc:
        raise InputError(f"{option}: {exc}") from None
    if not value > 0.0:
        raise InputError(f"{option}: must be positive, got {text.strip()!r}")
    return value


def _sieves(text):
    """Apertures (m) of a comma list, strictly ascending."""
    values = np.array([_quantity(v, "m", "--sieves") for v in text.split(",")])
    if np.any(np.diff(values) <= 0.0):
        raise InputError(f"--sieves: must be strictly ascending, got {', '.join(f'{v:g}' for v in _mm(values))} mm")
    return values


def _target(text, sieves):
    """Target percent passing at each sieve, checked as a passing curve."""
    from demcli.geometry import class_shares

    if sieves is None:
        raise InputError("--target needs --sieves (the apertures its values belong to)")
    try:
        passing = np.array([float(v) for v in text.split(",")])
        class_shares(sieves, passing)
    except ValueError as exc:
        raise InputError(f"--target: {exc}") from None
    return passing


def _require(path, kind, method):
    """Refuse inertia_square for a kind it is not defined for (clumps, polygons)."""
    if method == "inertia_square":
        raise InputError(f"{path}: --method inertia_square sizes polyhedra and spheres, and this file holds "
                         f"{kind}: use projection, volume_sphere or volume_cube")


# ---------------------------------------------------------------------------------------
# sizing one particle
# ---------------------------------------------------------------------------------------

def _equivalent_size(volume, method, dim):
    """Diameter of the sphere (volume_sphere) or edge of the cube (volume_cube) of equal volume;
    in 2D the circle's diameter or the square's side of equal area. m."""
    if method == "volume_sphere":
        return (6.0 * volume / math.pi) ** (1.0 / 3.0) if dim == 3 else math.sqrt(4.0 * volume / math.pi)
    return volume ** (1.0 / dim)


def _polyhedron_row(poly, method):
    """Sieve size, volume, least-shadow rectangle and shape indices of a ConvexPolyhedron; the
    flaky and elongated flags are against its own sieve size."""
    from demcli.geometry import projection_sieve, shape_indices, sieve_size

    shadow = projection_sieve(poly)
    size = shadow.size if method == "projection" else sieve_size(poly, method)
    ind = shape_indices(poly, reference_size=size)
    return dict(kind="polyhedron", sieve_size=size, volume=poly.volume, shadow_length=shadow.length,
                shadow_width=shadow.width, length=ind.length, intermediate=ind.intermediate, short=ind.short,
                elongation=ind.elongation, flatness=ind.flatness, flaky=int(ind.flaky), elongated=int(ind.elongated))


def _polygon_row(points, method):
    """Sieve size, area and bounding rectangle of the convex hull of 2D points."""
    from demcli.geometry import convex_hull_2d, min_bounding_rectangle, polygon_area, polygon_sieve_size

    hull = convex_hull_2d(points)
    length, width, _ = min_bounding_rectangle(hull)
    area = polygon_area(hull)
    size = polygon_sieve_size(hull) if method == "projection" else _equivalent_size(area, method, 2)
    return dict(kind="polygon", sieve_size=size, volume=area, shadow_length=length, shadow_width=width)


def _ball_row(centres, radii, volume, method):
    """Sieve size of a sphere body: one sphere (its diameter), or a clump of several balls
    (projection of the balls: exact for equal balls, sampled surfaces otherwise)."""
    from demcli.geometry import clump_sieve_size, sphere_sieve_sizes
    from demcli.geometry.carving import lattice_clump_sieve_size

    if method in VOLUME_METHODS:
        size = _equivalent_size(volume, method, 3)
    elif len(radii) == 1:
        size = float(sphere_sieve_sizes(radii)[0])
    elif np.ptp(radii) == 0.0:
        size = lattice_clump_sieve_size(centres, radii[0])
    else:
        size = clump_sieve_size(centres, radii)
    return dict(kind="sphere" if len(radii) == 1 else "clump", sieve_size=size, volume=volume)


def _each(path, items, size_one):
    """Rows ``size_one(item)`` labelled ``particle`` for (label, item) pairs; a degenerate
    particle is an InputError naming the file and the particle."""
    from demcli.geometry import GeometryError

    rows = []
    for label, item in items:
        try:
            rows.append(dict(size_one(item), particle=str(label)))
        except GeometryError as exc:
            raise InputError(f"{path}: particle {label}: {exc}") from None
    return rows


# ---------------------------------------------------------------------------------------
# state files
# ---------------------------------------------------------------------------------------

def _state_rows(path, method):
    """(dim, rows) of the particles of a state file."""
    from demcli.engine.actors import remove_actors
    from demcli.stages.base import load_stage_types
    from demcli.state import read_state

    load_stage_types()  # registers the stage-specific groups (polyhedra, polygons, aggregates, ...)
    state = read_state(path)
    if "polygons" in state.groups:
        _require(path, "polygons", method)
        poly = state.groups["polygons"]
        start, vertices = np.asarray(poly["vertex_start"]), np.asarray(poly["vertices"], float)
        items = ((p, vertices[start[p]:start[p + 1]]) for p in range(len(start) - 1))
        return 2, _each(path, items, lambda v: _polygon_row(v, method))
    groups = remove_actors(state.groups)
    agg = groups.get("aggregates", {})
    keep = np.asarray(agg["body"]) if "body" in agg else np.arange(len(groups["bodies"]["mass"]))
    return 3, _state_sphere_bodies(path, groups, keep, method) + _state_polyhedra(path, groups, keep, method)


def _state_sphere_bodies(path, groups, keep, method):
    """Rows of the sphere bodies among ``keep`` (single spheres and clumps, in body order)."""
    sp = groups["spheres"]
    owner = np.asarray(sp["body"], np.int64)
    sel = np.flatnonzero(np.isin(owner, keep))
    sel = sel[np.argsort(owner[sel], kind="stable")]
    bodies, first, count = np.unique(owner[sel], return_index=True, return_counts=True)
    if np.any(count > 1):
        _require(path, "clumps", method)
    mass = np.asarray(groups["bodies"]["mass"], float)[bodies]
    density = np.asarray(groups["materials"]["density"], float)[np.asarray(sp["material"])[sel[first]]]
    offset, radius = np.asarray(sp["offset"], float)[sel], np.asarray(sp["radius"], float)[sel]

    def one(k):
        members = slice(first[k], first[k] + count[k])
        return dict(_ball_row(offset[members], radius[members], mass[k] / density[k], method), mass=mass[k])

    return _each(path, zip(bodies, range(len(bodies))), one)


def _state_polyhedra(path, groups, keep, method):
    """Rows of the polyhedral bodies among ``keep``; bodies sharing a template are sized once."""
    if "polyhedra" not in groups:
        return []
    from demcli.geometry import convex_hull
    from demcli.state.polyhedra import ShapeTable

    table = ShapeTable.from_group(groups["polyhedron_shapes"])
    shape = np.asarray(groups["polyhedra"]["shape"], np.int64)
    mass = np.asarray(groups["bodies"]["mass"], float)
    first = len(mass) - len(shape)  # the polyhedra are the last bodies (state.polyhedra.first_polyhedral_body)
    sized = {}

    def one(b):
        k = int(shape[b - first])
        if k not in sized:
            sized[k] = _polyhedron_row(convex_hull(table.shape(k)[0]), method)
        return dict(sized[k], mass=mass[b])

    bodies = np.intersect1d(np.arange(first, len(mass)), keep)
    return _each(path, zip(bodies, bodies), one)


# ---------------------------------------------------------------------------------------
# meshes and vertex tables
# ---------------------------------------------------------------------------------------

def _part_rows(path, dim, parts, method, density):
    """Rows of point sets {label: (n, dim) m}, each sized as its convex hull."""
    from demcli.geometry import convex_hull

    if dim == 2:
        _require(path, "polygons", method)
        return _each(path, parts.items(), lambda p: _polygon_row(p, method))

    def one(points):
        row = _polyhedron_row(convex_hull(points), method)
        return row if density is None else dict(row, mass=density * row["volume"])

    return _each(path, parts.items(), one)


def _mesh_parts(path, scale):
    """{part index: vertices (n, 3), m} of the connected parts of a mesh file (vertices at the
    same place are one); a file of points without cells is one part."""
    import meshio
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # meshio's ASCII STL test overflows a numpy integer, harmlessly
            mesh = getattr(meshio, MESH_FORMATS[path.suffix.lower()]).read(str(path))
    except (meshio.ReadError, ValueError, IndexError, KeyError, EOFError, OSError) as exc:
        raise InputError(f"{path}: cannot read the mesh ({str(exc).strip() or type(exc).__name__})") from None
    points = np.asarray(mesh.points, float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise InputError(f"{path}: the mesh has no 3D vertices")
    i, j = _cell_links(mesh.cells)
    if len(i) and max(i.max(), j.max()) >= len(points):
        raise InputError(f"{path}: a cell refers to vertex {max(i.max(), j.max()) + 1}, the mesh has {len(points)}")
    if not len(i):
        return {0: points * scale}
    unique, inverse = np.unique(points, axis=0, return_inverse=True)
    i, j, n = inverse.reshape(-1)[i], inverse.reshape(-1)[j], len(unique)
    _, label = connected_components(coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)), directed=False)
    used = np.zeros(n, bool)
    used[i] = used[j] = True
    return {k: unique[used & (label == c)] * scale for k, c in enumerate(np.unique(label[used]))}


def _cell_links(cells):
    """(i, j) vertex pairs joining each vertex of every cell to the cell's first vertex."""
    firsts, others = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for block in cells:
        data = np.asarray(block.data, np.int64)
        if data.ndim == 2 and data.shape[1] > 1:
            firsts.append(np.repeat(data[:, 0], data.shape[1] - 1))
            others.append(data[:, 1:].ravel())
    return np.concatenate(firsts), np.concatenate(others)


def _csv_parts(path, scale):
    """(dim, {particle label: points (n, dim), m}) of a vertex table, labels in order of appearance."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            lines = [(k, row) for k, row in enumerate(csv.reader(fh), 1)
                     if row and row[0].strip() and not row[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot read the table ({exc})") from None
    header = [h.strip().lower() for h in lines[0][1]] if lines else []
    if header not in (["particle", "x", "y", "z"], ["particle", "x", "y"]):
        raise InputError(f"{path}: the header is {','.join(header) or 'missing'}; expected particle,x,y,z "
                         "(3D particles) or particle,x,y (2D polygons), coordinates in --unit")
    parts = {}
    for k, row in lines[1:]:
        if len(row) != len(header):
            raise InputError(f"{path}: line {k}: {len(row)} values, expected {len(header)} ({','.join(header)})")
        try:
            parts.setdefault(row[0].strip(), []).append([float(v) for v in row[1:]])
        except ValueError:
            raise InputError(f"{path}: line {k}: not a number among {','.join(row[1:])}") from None
    return len(header) - 1, {label: np.array(p) * scale for label, p in parts.items()}


# ---------------------------------------------------------------------------------------
# sieving and outputs
# ---------------------------------------------------------------------------------------

def _grade(rows, dim, method, sieves, target):
    """The SieveResult of sized rows: passing by mass where every particle has one."""
    from demcli.geometry import class_shares, compare_gradation, sieve_set

    masses = np.array([r.get("mass", np.nan) for r in rows], float)
    weight = "mass" if np.all(np.isfinite(masses)) else ("volume" if dim == 3 else "area")
    if weight != "mass":
        masses = np.array([r["volume"] for r in rows], float)
    result = SieveResult(rows, dim, method, weight)
    if sieves is None:
        return result
    passing = sieve_set([r["sieve_size"] for r in rows], masses, sieves)
    comparison = compare_gradation(sieves, target, passing) if target is not None else None
    return replace(result, sieves=sieves, passing=passing, shares=class_shares(sieves, passing), target=target,
                   comparison=comparison)


def _cell(value, factor):
    """A CSV field: '' for a missing value, text and flags as they are, numbers in full precision."""
    if value is None:
        return ""
    return str(value) if factor is None else repr(float(value) * factor)


def _csv_text(header, rows):
    """CSV text of a header and rows of fields."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


def _mm(lengths):
    """Lengths in m as mm, to 12 significant digits (16 mm, not 16.000000000000004)."""
    return np.array([float(f"{1e3 * v:.12g}") for v in lengths])


def _gradation_columns(result):
    """{column: values} of passing.csv and of classes.csv (the class shares, with the target)."""
    mm = _mm(result.sieves)
    passing = {"sieve[mm]": mm, "passing[%]": result.passing}
    classes = {"lower[mm]": np.concatenate([[0.0], mm]), "upper[mm]": np.concatenate([mm, [np.inf]]),
               "share[%]": result.shares}
    if result.comparison is not None:
        passing["target[%]"] = result.target
        classes.update({"target[%]": result.comparison.target, "difference[%]": result.comparison.difference})
    return passing, classes


def _tables(result):
    """{file name: (header, rows)}: particles.csv and, with sieves, passing.csv and classes.csv."""
    cols = [c for c in COLUMNS if any(c[0] in r for r in result.rows)]  # the columns some particle has
    header = [h.replace("volume[m^3]", "area[m^2]") if result.dim == 2 else h for _, h, _ in cols]
    tables = {"particles.csv": (header, [[_cell(r.get(k), f) for k, _, f in cols] for r in result.rows])}
    if result.sieves is not None:
        for name, columns in zip(("passing.csv", "classes.csv"), _gradation_columns(result)):
            tables[name] = (list(columns), [[repr(float(v)) for v in row] for row in zip(*columns.values())])
    return tables


def _figure(result):
    """The passing curve (and the target) over the sieve sizes, or None without matplotlib."""
    from demcli.state.plots import axis_label, line_figure

    mm = _mm(result.sieves)
    series = {"Sieved": (mm, result.passing)}
    if result.target is not None:
        series["Target"] = (mm, result.target)
    return line_figure(series, xlabel=axis_label("sieve size", "mm"), logx=True, xticks=mm,
                       ylabel=axis_label(f"passing by {result.weight}", "%"))


def _write(result, out):
    """Write the tables (and passing.png) into ``out`` atomically; the paths written."""
    from demcli.state.atomic import atomic_write_text
    from demcli.state.plots import save_png

    files = []
    for name, (header, rows) in _tables(result).items():
        atomic_write_text(out / name, _csv_text(header, rows))
        files.append(out / name)
    if result.sieves is not None and save_png(_figure(result), out / "passing.png"):
        files.append(out / "passing.png")
    return tuple(files)


def _headline(result):
    """``3 particles from 1 file (2 polyhedra, 1 sphere); sieve size by projection, passing by mass``."""
    kinds = {}
    for r in result.rows:
        kinds[r["kind"]] = kinds.get(r["kind"], 0) + 1
    n, files = len(result.rows), len({r["file"] for r in result.rows})
    what = ", ".join(f"{count} {kind if count == 1 else PLURAL[kind]}" for kind, count in kinds.items())
    return (f"{n} particle{'s' * (n != 1)} from {files} file{'s' * (files != 1)} ({what}); "
            f"sieve size by {result.method}, passing by {result.weight}")


def _aligned(columns):
    """Lines of a right-aligned text table of {header: values}: sizes as %g, percents with 2 decimals."""
    cells = [[h] + [f"{v:g}" if h.endswith("[mm]") else f"{v:.2f}" for v in vals] for h, vals in columns.items()]
    widths = [max(map(len, col)) for col in cells]
    return ["  ".join(c.rjust(w) for c, w in zip(line, widths)) for line in zip(*cells)]
