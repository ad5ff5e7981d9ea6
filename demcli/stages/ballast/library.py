"""``ballast_library`` stage: random convex polyhedra, sized and filed by sieve class.

Seed 002, section 2 (Shao, Lian & Yang 2017): "generate many random convex
polyhedra, size them, store them by size class (10 000 per class) in HDF5". The
stage reads the classes of the previous ``gradation`` state and, for every class
with a positive lower bound, makes ``per_class`` particles:

1. a random angular shape at length ~1 (:func:`demcli.geometry.ballast_shapes.
   random_ballast_shape`: Voronoi cells by default, the route Eliáš took for ballast);
2. its sieve size s_1 by :func:`demcli.geometry.sieve_size` (projection method by
   default) and its principal frame and unit-density inertia;
3. a target size s drawn uniformly inside the class (lower, upper), and the shape
   scaled by s / s_1: the sieve size, like every length, is linear in the scale, so
   one sieve evaluation per particle suffices (volume x scale^3, inertia x scale^5);
4. flaky and elongated flags against the class's mean size (:func:`demcli.geometry.
   shape_indices`, BS 812-105 gauges 0.6 and 1.8 by default).

Every particle has its own random stream, ``SeedSequence(seed, spawn_key=(class,
i))``, so the library is the same bit for bit whatever the number of worker
processes.

Libraries are content-addressed: the file is ``<directory>/<hash>.h5`` where the hash
is the sha256 of the generator config (seed, per_class, shape parameters, sieve
method, gauge ratios, class bounds, file format version). Cases that ask for the same
library share one file (default directory: ``_library`` beside the run folders, i.e.
``runs/_library``); it is written atomically and rebuilt if missing or damaged. The
stage's own state only records the library (``library/*``: path, hash, generator and
per-class statistics) and passes the gradation on.

Library file layout (HDF5; attributes ``format``, ``version``, ``hash``, ``generator``):

- ``classes/{lower, upper}`` (m) and ``classes/start``: particles of class k are the
  rows ``start[k]:start[k + 1]``;
- ``particles/*`` one row per particle: ``class``, ``sieve_size`` (m), ``volume``
  (m^3), ``length``/``intermediate``/``short`` (m, extents along the principal axes),
  ``elongation`` (I/L), ``flatness`` (S/I), ``flaky``, ``elongated``, ``n_faces``;
- ``shapes/*``: the shapes at their library size in their principal frame, in the
  CSR layout of the state group ``polyhedron_shapes`` (:mod:`demcli.state.polyhedra`):
  vertices, faces, face normals and offsets, edges, volume, principal moments of
  inertia for unit density (m^5), circumradius.
"""

import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from demcli.config.case import seed_field
from demcli.config.schema import Float, Int, Optional, Section, Str, Tagged
from demcli.errors import StageError, StateError
from demcli.stages.base import StageType, earlier_stage, register_stage
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

describe_column("flaky", "Flaky share", "%", table="library", doc="percent of the class's particles that are flaky")
describe_column("elongated", "Elongated share", "%", table="library",
                doc="percent of the class's particles that are elongated")

LIBRARY_FORMAT = "demcli ballast library"
LIBRARY_VERSION = 1
SIEVE_METHODS = ("projection", "volume_sphere", "volume_cube", "inertia_square")
# target sizes are drawn in [lower + m (upper - lower), upper - m (upper - lower)] so that
# round-off in the scaled sieve size can never move a particle across a class bound
_SIZE_MARGIN = 1e-6

register_group("library", "The ballast library a stage built or reused, and its per-class statistics",
               writer="stage ballast_library")
_L = dict(writer="stage ballast_library")
register(Field("library/path", "str", (), "", "library file (HDF5), absolute", attr=True, **_L))
register(Field("library/hash", "str", (), "", "sha256 of the generator config (names the file)", attr=True, **_L))
register(Field("library/generator", "str", (), "", "generator config, canonical JSON", attr=True, **_L))
for _name, _kind, _unit, _doc in [
        ("class_lower", "f", "m", "lower size of each library class"),
        ("class_upper", "f", "m", "upper size of each library class"),
        ("class_count", "i", "", "particles in each class"),
        ("mean_volume", "f", "m^3", "mean particle volume"),
        ("mean_elongation", "f", "1", "mean elongation ratio I/L"),
        ("mean_flatness", "f", "1", "mean flatness ratio S/I"),
        ("flaky_share", "f", "%", "flaky particles, percent by number"),
        ("elongated_share", "f", "%", "elongated (needle) particles, percent by number")]:
    register(Field(f"library/{_name}", _kind, ("n_lib_class",), _unit, _doc, **_L))


def _range(lo, hi, doc):
    def check(node, report):
        if node.max < node.min:
            report("max", f"must be >= min ({node.min:g})", node.max)
    return Section({"min": Float(min=0, max=1, min_inclusive=False), "max": Float(min=0, max=1, min_inclusive=False)},
                   doc=doc, check=check, default={"min": lo, "max": hi})


def _faces(lo, hi):
    def check(node, report):
        if node.max < node.min:
            report("max", f"must be >= min ({node.min})", node.max)
    return Section({"min": Int(min=4), "max": Int(min=4)}, doc="face count range (draws outside are repeated)",
                   check=check, default={"min": lo, "max": hi})


_COMMON = {
    "faces": _faces(8, 30),
    "elongation": _range(0.55, 0.95, "elongation I/L, drawn uniformly (Zingg 1935)"),
    "flatness": _range(0.5, 0.95, "flatness S/I, drawn uniformly"),
}
SHAPE = Tagged("method", {
    "voronoi": Section({
        **_COMMON,
        "regularity": Float(min=0, max=1, default=0.5,
                            doc="hard-core distance of the Voronoi seeds (0: Poisson-Voronoi cells)"),
        "min_edge": Float(min=0, max=0.5, max_inclusive=False, default=0.05,
                          doc="vertices closer than this fraction of the length are merged"),
    }, doc="Voronoi cells of hard-core random seeds (Eliáš 2014)"),
    "hull": Section(dict(_COMMON), doc="hulls of random points on an ellipsoid (triangular faces)"),
}, default={"method": "voronoi"}, doc="shape generator")

FIELDS = {
    "per_class": Int(min=1, default=500, doc="particles per size class (Shao et al. 2017: 10 000)"),
    "seed": Optional(seed_field("seed of the library (0 to 2^63 - 1; default: the case seed)")),
    "shape": SHAPE,
    "sieve_method": Str(choices=list(SIEVE_METHODS), default="projection", doc="how particles are sized"),
    "flaky_ratio": Float(min=0, max=1, min_inclusive=False, default=0.6,
                         doc="flaky: short side < ratio x class mean size (BS 812-105.1)"),
    "elongated_ratio": Float(min=1, default=1.8,
                             doc="elongated (needle): length > ratio x class mean size (BS 812-105.2)"),
    "directory": Optional(Str(), doc="folder of the shared libraries (default: _library beside the run folder)"),
    "workers": Int(min=0, default=1, doc="worker processes for building (0: one per core)"),
}


# ---------------------------------------------------------------------------------------
# building
# ---------------------------------------------------------------------------------------

def library_classes(lower, upper):
    """Indices of the gradation classes a library covers: positive lower bound, non-empty."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    return np.flatnonzero((lower > 0.0) & (upper > lower))


def generator_config(cfg, seed, lower, upper):
    """The generator config (plain JSON-able dict) that names a library."""
    shape = cfg.shape.to_dict() if hasattr(cfg.shape, "to_dict") else dict(cfg.shape)
    return {"format": LIBRARY_FORMAT, "version": LIBRARY_VERSION, "seed": int(seed), "per_class": int(cfg.per_class),
            "shape": shape, "sieve_method": cfg.sieve_method, "flaky_ratio": float(cfg.flaky_ratio),
            "elongated_ratio": float(cfg.elongated_ratio),
            "classes": [[float(lo), float(hi)] for lo, hi in zip(lower, upper)]}


def generator_hash(gen):
    from demcli.config.schema import sha256_of

    return sha256_of(gen)


def shape_params(shape):
    """ShapeParams of a generator's ``shape`` dict."""
    from demcli.geometry.ballast_shapes import ShapeParams

    kw = dict(method=shape["method"], faces=(int(shape["faces"]["min"]), int(shape["faces"]["max"])),
              elongation=(shape["elongation"]["min"], shape["elongation"]["max"]),
              flatness=(shape["flatness"]["min"], shape["flatness"]["max"]))
    if shape["method"] == "voronoi":
        kw.update(regularity=shape["regularity"], min_edge=shape["min_edge"])
    return ShapeParams(**kw)


def _particle_rng(seed, k, i):
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=(int(k), int(i)))))


def build_chunk(task):
    """Particles i0..i1-1 of class k (a worker's unit of work; picklable in and out).

    task: (generator dict, k, i0, i1). Returns (ShapeTable, dict of per-particle arrays).
    """
    from demcli.geometry import shape_indices, sieve_size
    from demcli.geometry.ballast_shapes import random_ballast_shape
    from demcli.state.polyhedra import ShapeTable

    gen, k, i0, i1 = task
    params = shape_params(gen["shape"])
    lo, hi = gen["classes"][k]
    mean_size = 0.5 * (lo + hi)
    polys, scales = [], []
    cols = {name: [] for name in ("sieve_size", "length", "intermediate", "short", "elongation", "flatness",
                                  "flaky", "elongated", "n_faces")}
    for i in range(i0, i1):
        rng = _particle_rng(gen["seed"], k, i)
        poly = random_ballast_shape(rng, params)
        s1 = sieve_size(poly, gen["sieve_method"])
        u = _SIZE_MARGIN + (1.0 - 2.0 * _SIZE_MARGIN) * rng.random()
        s = lo + (hi - lo) * u
        scale = s / s1
        ind = shape_indices(poly, reference_size=mean_size / scale, flaky_ratio=gen["flaky_ratio"],
                            elongated_ratio=gen["elongated_ratio"])
        polys.append(poly)
        scales.append(scale)
        cols["sieve_size"].append(s1 * scale)
        cols["length"].append(ind.length * scale)
        cols["intermediate"].append(ind.intermediate * scale)
        cols["short"].append(ind.short * scale)
        cols["elongation"].append(ind.elongation)
        cols["flatness"].append(ind.flatness)
        cols["flaky"].append(ind.flaky)
        cols["elongated"].append(ind.elongated)
        cols["n_faces"].append(poly.n_faces)
    table = ShapeTable.from_polyhedra(polys, scales)
    out = {name: np.asarray(v, dtype=bool if name in ("flaky", "elongated") else
                            np.int64 if name == "n_faces" else np.float64) for name, v in cols.items()}
    out["class"] = np.full(i1 - i0, k, dtype=np.int64)
    out["volume"] = table.volume.copy()
    return table, out


def _chunks(gen, size=100):
    n = gen["per_class"]
    return [(gen, k, i0, min(n, i0 + size)) for k in range(len(gen["classes"])) for i0 in range(0, n, size)]


def build_library(gen, workers=1, log=None):
    """Build a library in memory: (Library, seconds). ``workers`` > 1 uses processes (spawned)."""
    from demcli.state.polyhedra import ShapeTable

    tasks = _chunks(gen)
    t0 = time.perf_counter()
    n_total = gen["per_class"] * len(gen["classes"])
    results = []
    next_log = t0 + 10.0

    def progress():
        nonlocal next_log
        if log is not None and time.perf_counter() > next_log:
            done = sum(len(r[0]) for r in results)
            rate = done / (time.perf_counter() - t0)
            log(f"  {done}/{n_total} particles, {rate:.0f}/s, ETA {(n_total - done) / rate:.0f} s")
            next_log += 10.0

    if workers > 1 and len(tasks) > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            for res in pool.map(build_chunk, tasks):  # in task order
                results.append(res)
                progress()
    else:
        for task in tasks:
            results.append(build_chunk(task))
            progress()
    seconds = time.perf_counter() - t0
    table = ShapeTable.concat([r[0] for r in results])
    particles = {name: np.concatenate([r[1][name] for r in results]) for name in results[0][1]}
    counts = np.bincount(particles["class"], minlength=len(gen["classes"]))
    start = np.zeros(len(counts) + 1, dtype=np.int64)
    start[1:] = np.cumsum(counts)
    bounds = np.asarray(gen["classes"], dtype=np.float64).reshape(-1, 2)
    lib = Library(gen=gen, hash=generator_hash(gen), lower=bounds[:, 0], upper=bounds[:, 1], start=start,
                  particles=particles, shapes=table)
    return lib, seconds


# ---------------------------------------------------------------------------------------
# the library file
# ---------------------------------------------------------------------------------------

_UNITS = {"sieve_size": "m", "volume": "m^3", "length": "m", "intermediate": "m", "short": "m",
          "elongation": "1", "flatness": "1", "flaky": "", "elongated": "", "n_faces": "", "class": "",
          "lower": "m", "upper": "m", "start": "", "vertices": "m", "face_normal": "1", "face_offset": "m",
          "inertia": "m^5", "radius": "m"}


@dataclass(frozen=True, eq=False)
class Library:
    """A ballast library in memory (see the module docstring for the file layout)."""

    gen: dict
    hash: str
    lower: np.ndarray
    upper: np.ndarray
    start: np.ndarray
    particles: dict
    shapes: object  # ShapeTable

    def __len__(self):
        return len(self.particles["class"])

    def class_rows(self, k):
        return np.arange(self.start[k], self.start[k + 1])

    def find_class(self, lower, upper, rtol=1e-9):
        """Index of the library class with these bounds (m), or None."""
        hit = np.flatnonzero(np.isclose(self.lower, lower, rtol=rtol, atol=0)
                             & np.isclose(self.upper, upper, rtol=rtol, atol=0))
        return int(hit[0]) if len(hit) else None


def write_library(path, lib):
    """Write ``lib`` to ``path`` atomically and deterministically (same library, same bytes)."""
    import h5py

    from demcli import __version__
    from demcli.config.schema import canonical_json
    from demcli.state.atomic import atomic_path

    groups = {"classes": {"lower": lib.lower, "upper": lib.upper, "start": lib.start},
              "particles": lib.particles, "shapes": lib.shapes.to_group()}
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w", libver="earliest") as f:
            for key, value in sorted({"format": LIBRARY_FORMAT, "version": np.int64(LIBRARY_VERSION),
                                      "hash": lib.hash, "generator": canonical_json(lib.gen),
                                      "created_by": f"demcli {__version__}"}.items()):
                f.attrs[key] = value
            for gname in sorted(groups):
                grp = f.create_group(gname)
                for name in sorted(groups[gname]):
                    arr = np.ascontiguousarray(groups[gname][name])
                    ds = grp.create_dataset(name, data=arr, track_times=False)
                    ds.attrs["unit"] = _UNITS.get(name, "")
    return Path(path)


def read_library(path, expect_hash=None):
    """Read a library file; StateError if it is not one, or not the expected library."""
    import h5py

    from demcli.state.polyhedra import ShapeTable

    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            fmt, version = f.attrs.get("format"), f.attrs.get("version")
            if fmt != LIBRARY_FORMAT:
                raise StateError(f"{path}: not a {LIBRARY_FORMAT} file")
            if int(version) != LIBRARY_VERSION:
                raise StateError(f"{path}: library format version {version}, this demcli reads {LIBRARY_VERSION}")
            h = str(f.attrs["hash"])
            if expect_hash is not None and h != expect_hash:
                raise StateError(f"{path}: holds library {h[:12]}, expected {expect_hash[:12]}")
            gen = json.loads(f.attrs["generator"])
            cls = {k: f["classes"][k][()] for k in f["classes"]}
            particles = {k: f["particles"][k][()] for k in f["particles"]}
            shapes = ShapeTable.from_group({k: f["shapes"][k][()] for k in f["shapes"]})
    except (OSError, KeyError) as exc:
        raise StateError(f"{path}: unreadable library file ({exc})") from None
    return Library(gen=gen, hash=h, lower=cls["lower"], upper=cls["upper"], start=cls["start"],
                   particles=particles, shapes=shapes)


def library_path(directory, gen_hash):
    return Path(directory) / f"{gen_hash[:24]}.h5"


def ensure_library(gen, directory=None, path=None, workers=1, log=None):
    """The library of ``gen``: read from its content-addressed file, or built and written.

    Returns (Library, path, info) where info is {"built": bool, "seconds": float}.
    """
    h = generator_hash(gen)
    path = Path(path) if path is not None else library_path(directory, h)
    if path.exists():
        try:
            lib = read_library(path, expect_hash=h)
            return lib, path, {"built": False, "seconds": 0.0}
        except StateError as exc:
            if log:
                log(f"rebuilding the library: {exc}")
    n = gen["per_class"] * len(gen["classes"])
    if log:
        log(f"building library {h[:12]}: {len(gen['classes'])} classes x {gen['per_class']} particles "
            f"({gen['shape']['method']} shapes, {workers} worker{'s' if workers > 1 else ''})")
    lib, seconds = build_library(gen, workers=workers, log=log)
    write_library(path, lib)
    if log:
        log(f"library built: {n} particles in {seconds:.2f} s ({n / max(seconds, 1e-9):.0f} particles/s) -> {path}")
    return lib, path, {"built": True, "seconds": seconds}


# ---------------------------------------------------------------------------------------
# the stage
# ---------------------------------------------------------------------------------------

def empty_bodies():
    return {"x": np.zeros((0, 3)), "v": np.zeros((0, 3)), "q": np.zeros((0, 4)), "omega": np.zeros((0, 3)),
            "mass": np.zeros(0), "inertia": np.zeros((0, 3)), "id": np.zeros(0, np.int64),
            "flags": np.zeros(0, np.int8)}


def empty_spheres():
    return {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)), "radius": np.zeros(0),
            "material": np.zeros(0, np.int64)}


def library_group(lib):
    """Per-class statistics of a library (the ``library/*`` datasets)."""
    p = lib.particles
    rows = [lib.class_rows(k) for k in range(len(lib.lower))]

    def stat(fn):
        return np.array([fn(r) if len(r) else 0.0 for r in rows], dtype=np.float64)

    return {"class_lower": lib.lower, "class_upper": lib.upper, "class_count": np.diff(lib.start).astype(np.int64),
            "mean_volume": stat(lambda r: p["volume"][r].mean()),
            "mean_elongation": stat(lambda r: p["elongation"][r].mean()),
            "mean_flatness": stat(lambda r: p["flatness"][r].mean()),
            "flaky_share": stat(lambda r: 100.0 * p["flaky"][r].mean()),
            "elongated_share": stat(lambda r: 100.0 * p["elongated"][r].mean())}


def particle_volume_bound(cfg, size):
    """Largest volume [m^3] a particle of sieve size ``size`` [m] in the library of ``cfg`` can
    have. volume_sphere and volume_cube fix it; a particle that passes a square hole of side s
    (projection, inertia_square) has a cross-section within s^2 and a length L <= I / e_min with
    its intermediate size I <= sqrt(2) s, so V <= sqrt(2) s^3 / e_min (e_min: shape.elongation.min;
    generated shapes stay below a third of this)."""
    if cfg.sieve_method == "volume_sphere":
        return math.pi / 6.0 * size ** 3
    if cfg.sieve_method == "volume_cube":
        return size ** 3
    return math.sqrt(2.0) * size ** 3 / cfg.shape.elongation.min


def _case_check(cfg, case, k, scene, report):
    """A library for an assemble stage must be able to fill every class of the gradation it
    is built for: per_class particles, each at most :func:`particle_volume_bound`."""
    from demcli.config.memory import BYTES_PER_POLYHEDRON, check_memory
    from demcli.stages.specimen.gradation import compute

    grading = earlier_stage(case, k, "gradation")
    if grading is None:
        return
    res = compute(grading)
    lower, upper, amount = res["class_lower"], res["class_upper"], res["class_amount"]
    keep = library_classes(lower, upper)
    if not len(keep):
        report("", f"the gradation of stage {grading.name!r} has no class with a positive lower size to build a "
               "library for", hint="set its volumetrics.min_size")
        return
    check_memory(report, "per_class", cfg.per_class * len(keep), f"the library of {len(keep)} classes", cfg.per_class,
                 "polyhedra", BYTES_PER_POLYHEDRON)
    if not any(c.type == "assemble" for c in case.stages[k + 1:]):
        return
    short = [(amount[j] / particle_volume_bound(cfg, upper[j]), j) for j in keep if amount[j] > 0]
    need, j = max(short, default=(0.0, None))
    if need > cfg.per_class:
        vmax = particle_volume_bound(cfg, upper[j]) * 1e6
        report("per_class", f"class {lower[j] * 1e3:g}-{upper[j] * 1e3:g} mm of stage {grading.name!r} needs "
               f"{amount[j] * 1e6:.4g} cm^3 of ballast, more than {cfg.per_class} particles of at most "
               f"{vmax:.3g} cm^3 can hold", cfg.per_class, f"raise per_class to at least {math.ceil(need)}")


def default_directory(ctx):
    return ctx.runner.run_dir.resolve().parent / "_library"


def run(ctx, cfg, state_in):
    from demcli.config.schema import canonical_json
    from demcli.state import RecordTable

    g = state_in.groups["gradation"]
    keep = library_classes(g["class_lower"], g["class_upper"])
    if not len(keep):
        raise StageError(f"stage {ctx.name}: the gradation has no class with a positive lower size")
    seed = ctx.seed if cfg.seed is None else cfg.seed
    gen = generator_config(cfg, seed, g["class_lower"][keep], g["class_upper"][keep])
    directory = Path(cfg.directory).resolve() if cfg.directory else default_directory(ctx)
    workers = cfg.workers or os.cpu_count() or 1
    lib, path, info = ensure_library(gen, directory=directory, workers=workers, log=ctx.log)
    if not info["built"]:
        ctx.log(f"library {lib.hash[:12]} reused: {len(lib)} particles in {len(lib.lower)} classes ({path})")
    state = ctx.new_state()
    state.groups["bodies"] = empty_bodies()
    state.groups["spheres"] = empty_spheres()
    state.groups["gradation"] = {k: np.asarray(v) for k, v in g.items()}
    grp = library_group(lib)
    state.groups["library"] = grp
    state.group_attrs["library"] = {"path": str(path), "hash": lib.hash, "generator": canonical_json(gen)}
    table = RecordTable("library", {"lower": "mm", "upper": "mm", "count": "", "mean_volume": "cm^3",
                                    "mean_elongation": "1", "mean_flatness": "1", "flaky": "%", "elongated": "%"})
    for k in range(len(lib.lower)):
        table.append(lower=grp["class_lower"][k] * 1e3, upper=grp["class_upper"][k] * 1e3,
                     count=int(grp["class_count"][k]), mean_volume=grp["mean_volume"][k] * 1e6,
                     mean_elongation=grp["mean_elongation"][k], mean_flatness=grp["mean_flatness"][k],
                     flaky=grp["flaky_share"][k], elongated=grp["elongated_share"][k])
        ctx.log(f"  class {grp['class_lower'][k] * 1e3:g}-{grp['class_upper'][k] * 1e3:g} mm: "
                f"{grp['class_count'][k]} particles, mean volume {grp['mean_volume'][k] * 1e6:.3g} cm^3, "
                f"I/L {grp['mean_elongation'][k]:.2f}, S/I {grp['mean_flatness'][k]:.2f}, "
                f"flaky {grp['flaky_share'][k]:.0f} %, elongated {grp['elongated_share'][k]:.0f} %")
    table.to_state(state)
    ctx.write_records(table, x="upper", ys=["flaky", "elongated"])
    return state


register_stage(StageType(
    "ballast_library", FIELDS, run, needs_input=True, case_check=_case_check,
    requires=("gradation/class_lower", "gradation/class_upper"),
    provides=("bodies/*", "spheres/*", "library/*", "records/*"), keeps=("gradation",),
    doc="random convex polyhedra sized by sieve and filed by class in a shared, content-addressed HDF5 library"))
