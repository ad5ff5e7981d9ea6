"""Ballast library stage: sizing and filing by class, exact shape data, content addressing, reuse."""

from pathlib import Path

import numpy as np
import pytest

from demcli import run_case
from demcli.errors import ConfigError, StageError
from demcli.geometry import convex_hull, sieve_size
from demcli.stages.ballast.library import build_library, read_library, write_library
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"


@pytest.fixture(scope="module")
def wide(tmp_path_factory, ballast_library_dir):
    out = tmp_path_factory.mktemp("wide_smoke")
    run_case(CASES / "smoke" / "ballast_wide.yaml", out=out, quiet=True,
             overrides=[f"stages.library.directory={ballast_library_dir}"])
    return out


def test_particles_are_sized_filed_and_stored_exactly(wide):
    # Given the smoke library (6 classes x 120 Voronoi particles)
    st = read_state(wide / "01-library.h5")
    lib = read_library(st.group_attrs["library"]["path"])
    p = lib.particles
    assert len(lib) == 720 and np.diff(lib.start).tolist() == [120] * 6
    # Then every particle's sieve size lies inside its class
    lo, hi = lib.lower[p["class"]], lib.upper[p["class"]]
    assert np.all((p["sieve_size"] > lo) & (p["sieve_size"] < hi))
    rng = np.random.default_rng(0)
    for i in rng.choice(len(lib), 25, replace=False):
        v, faces, normals, offsets, edges = lib.shapes.shape(i)
        poly = convex_hull(v)
        # and the stored size is the projection sieve size of the stored vertices
        assert sieve_size(poly) == pytest.approx(p["sieve_size"][i], rel=1e-9)
        # the vertices are in the principal frame: centroid at the origin, inertia diagonal, ascending
        scale = np.ptp(v, axis=0).max()
        assert np.allclose(poly.centroid, 0.0, atol=1e-12 * scale)
        assert poly.volume == pytest.approx(lib.shapes.volume[i], rel=1e-12) == p["volume"][i]
        assert np.allclose(poly.inertia, np.diag(lib.shapes.inertia[i]), rtol=0, atol=1e-9 * poly.inertia.max())
        assert np.all(np.diff(lib.shapes.inertia[i]) >= 0)
        # each face's vertices lie on its plane, every vertex on the inner side of every plane
        assert np.all(v @ normals.T <= offsets + 1e-12 * scale)
        for f, n, d in zip(faces, normals, offsets):
            assert np.allclose(v[f] @ n, d, atol=1e-12 * scale)
        assert lib.shapes.radius[i] == pytest.approx(np.linalg.norm(v, axis=1).max())
        # flags against the class's mean size (BS 812 gauges 0.6 and 1.8)
        mean = 0.5 * (lo[i] + hi[i])
        assert p["flaky"][i] == (p["short"][i] < 0.6 * mean)
        assert p["elongated"][i] == (p["length"][i] > 1.8 * mean)
    # and the stage records per-class statistics
    assert st["library/class_count"].tolist() == [120] * 6
    assert (wide / "records" / "library_library.csv").exists()


def test_cases_with_the_same_generator_share_one_library(wide, tmp_path, ballast_library_dir):
    # Given the single-size smoke case, which asks for the same library as the wide one
    run_case(CASES / "smoke" / "ballast_single_large.yaml", out=tmp_path, quiet=True,
             overrides=[f"stages.library.directory={ballast_library_dir}"])
    a = read_state(wide / "01-library.h5").group_attrs["library"]
    b = read_state(tmp_path / "01-library.h5").group_attrs["library"]
    # Then it names the same file, reused rather than rebuilt
    assert a["hash"] == b["hash"] and a["path"] == b["path"]
    assert "reused" in (tmp_path / "log.txt").read_text()
    assert "building library" not in (tmp_path / "log.txt").read_text()


GEN = {"format": "demcli ballast library", "version": 1, "seed": 5, "per_class": 6,
       "shape": {"method": "voronoi", "faces": {"min": 8, "max": 30}, "elongation": {"min": 0.55, "max": 0.95},
                 "flatness": {"min": 0.5, "max": 0.95}, "regularity": 0.5, "min_edge": 0.05},
       "sieve_method": "projection", "flaky_ratio": 0.6, "elongated_ratio": 1.8,
       "classes": [[0.016, 0.025], [0.025, 0.0355]]}


def test_same_seed_same_library_bytes_for_any_worker_count(tmp_path):
    # Given one generator config built serially and by two worker processes
    a, _ = build_library(GEN, workers=1)
    b, _ = build_library(GEN, workers=2)
    write_library(tmp_path / "a.h5", a)
    write_library(tmp_path / "b.h5", b)
    # Then the files are identical byte for byte
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()
    # and another seed gives other particles
    c, _ = build_library({**GEN, "seed": 6})
    assert not np.array_equal(c.particles["sieve_size"], a.particles["sieve_size"])


SMALL = """\
name: tiny
seed: 3
materials:
  ballast: {density: 2600 kg/m^3, young: 4e11 Pa, poisson: 0.3, friction: 0.67}
stages:
  - name: grading
    type: gradation
    sieves:  [16 mm, 25 mm, 35.5 mm, 45 mm]
    passing: [PASSING]
    specimen: {shape: box, size: [0.12 m, 0.1 m, 0.06 m]}
    volumetrics: {kind: ballast, bulk_density: 1.72 g/cm^3, particle_density: 2.6 g/cm^3}
  - name: library
    type: ballast_library
    per_class: PER_CLASS
    directory: LIBDIR
  - name: assembly
    type: assemble
    box: {max: [0.12 m, 0.1 m, 0.06 m]}
    material: ballast
"""


def tiny_case(tmp_path, passing="0, 0, 100, 100", per_class=60):
    p = tmp_path / "tiny.yaml"
    p.write_text(SMALL.replace("PASSING", passing).replace("PER_CLASS", str(per_class))
                 .replace("LIBDIR", str(tmp_path / "lib")))
    return p


def test_a_missing_library_file_is_rebuilt(tmp_path):
    # Given a finished run whose library file is then deleted
    case = tiny_case(tmp_path)
    run_case(case, out=tmp_path / "run", quiet=True)
    path = Path(read_state(tmp_path / "run" / "01-library.h5").group_attrs["library"]["path"])
    before = read_state(tmp_path / "run" / "02-assembly.h5")
    path.unlink()
    # When the assembly is run again
    run_case(case, out=tmp_path / "run", quiet=True, only="assembly")
    # Then the library is rebuilt at the same place and the assembly comes out the same
    assert path.exists() and "rebuilt" in (tmp_path / "run" / "log.txt").read_text()
    after = read_state(tmp_path / "run" / "02-assembly.h5")
    assert np.array_equal(before["bodies/x"], after["bodies/x"])


def test_too_small_a_library_is_a_clear_error(tmp_path):
    with pytest.raises(StageError, match="raise the library's per_class to about"):
        run_case(tiny_case(tmp_path, per_class=5), out=tmp_path / "run", quiet=True)


def test_a_class_below_the_library_is_a_clear_error(tmp_path):
    # 10 % through the 16 mm sieve: a 0-16 mm class, which a library does not cover: refused
    # when the case is validated, before any stage runs
    with pytest.raises(ConfigError, match="0-16 mm .* no particles for it .*min_size"):
        run_case(tiny_case(tmp_path, passing="10, 10, 100, 100"), out=tmp_path / "run", quiet=True)
