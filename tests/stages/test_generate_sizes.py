"""Issue 33 item 5: size distributions of the generate stage and several particle sets per scene.

Draws are checked against their targets with stated tolerances; old cases against hashes of
their generate output recorded before the change; bad input against exit code 2.
"""

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.config.schema import validate_quietly
from demcli.geometry.sieve import sieve_set
from demcli.stages.specimen.sizes import SIZE, draw_amount, draw_radii

ROOT = Path(__file__).resolve().parents[2]
N = 20_000


def _dist(**kw):
    node = validate_quietly(SIZE, kw)
    assert node is not None, kw
    return node


# ---------------------------------------------------------------------------------------
# distributions (generation only, no DEM)
# ---------------------------------------------------------------------------------------

def test_sieve_draw_follows_the_mass_passing_curve():
    # Given a sieve curve by mass (diameters 2-16 mm, 0/20/55/100 % passing)
    sieves, passing = [2e-3, 4e-3, 8e-3, 16e-3], [0.0, 20.0, 55.0, 100.0]
    dist = _dist(distribution="sieve", sieves=sieves, passing=passing)
    # When 20 000 radii are drawn
    r = draw_radii(np.random.default_rng(1), dist, N)
    d = 2 * r
    # Then every diameter lies within the curve's range
    assert d.min() >= 2e-3 and d.max() <= 16e-3
    # and the mass passing each sieve is the curve's within 1 percentage point
    got = sieve_set(d, d ** 3, sieves)
    np.testing.assert_allclose(got, passing, atol=1.0)
    # and between sieves the passing is linear in log d (the stated within-class rule):
    # at sqrt(4 * 8) mm, half-way in log d, 20 + 35 / 2 = 37.5 % within 1.5 points
    mid = math.sqrt(4e-3 * 8e-3)
    assert sieve_set(d, d ** 3, [mid])[0] == pytest.approx(37.5, abs=1.5)


def test_sieve_draw_is_by_mass_not_by_number():
    # Given two equal-mass classes, 2-4 mm and 4-8 mm
    dist = _dist(distribution="sieve", sieves=[2e-3, 4e-3, 8e-3], passing=[0, 50, 100])
    d = 2 * draw_radii(np.random.default_rng(2), dist, N)
    # Then the fine class holds about <d^3>_coarse / <d^3>_fine = 8 times as many particles:
    # <d^3> = 3 ln(b/a) / (a^-3 - b^-3) scales with the size, so the number ratio is 2^3 (within 1 %)
    ratio = np.sum(d <= 4e-3) / np.sum(d > 4e-3)
    assert ratio == pytest.approx(8.0, rel=0.01)


def test_lognormal_median_and_geometric_std():
    # Given a lognormal radius of median 1 mm and geometric standard deviation 1.4
    dist = _dist(distribution="lognormal", median=1e-3, gsd=1.4)
    r = draw_radii(np.random.default_rng(3), dist, N)
    # Then the sample median and exp(std ln r) are within 2 % (their standard errors are
    # 1.2533 sigma / sqrt(N) = 0.3 % and sigma / sqrt(2 N) = 0.17 %)
    assert np.median(r) == pytest.approx(1e-3, rel=0.02)
    assert math.exp(np.std(np.log(r))) == pytest.approx(1.4, rel=0.02)
    # and mu/sigma of ln r give the same distribution
    same = _dist(distribution="lognormal", mu=math.log(1e-3), sigma=math.log(1.4))
    np.testing.assert_allclose(draw_radii(np.random.default_rng(3), same, 100), r[:100], rtol=1e-12)


def test_truncated_lognormal_stays_in_range_with_the_truncated_cdf():
    from scipy.special import ndtr

    # Given ln r ~ N(ln 1 mm, ln 1.5) truncated to [0.8, 1.5] mm
    dist = _dist(distribution="lognormal", median=1e-3, gsd=1.5, min=0.8e-3, max=1.5e-3)
    r = draw_radii(np.random.default_rng(4), dist, N)
    assert r.min() >= 0.8e-3 and r.max() <= 1.5e-3
    # Then P(r <= 1 mm) is the truncated CDF (Phi(0) - Phi(a)) / (Phi(b) - Phi(a)) within
    # 4 binomial standard errors sqrt(p (1 - p) / N) (about 0.0035)
    s = math.log(1.5)
    a, b = ndtr(math.log(0.8) / s), ndtr(math.log(1.5) / s)
    p = (0.5 - a) / (b - a)
    assert abs(np.mean(r <= 1e-3) - p) <= 4 * math.sqrt(p * (1 - p) / N)


@pytest.mark.parametrize("by", ["mass", "number"])
def test_discrete_fractions(by):
    # Given radii 1, 2, 3 mm with fractions 0.2, 0.3, 0.5 by mass or by number
    radii, w = np.array([1e-3, 2e-3, 3e-3]), np.array([0.2, 0.3, 0.5])
    dist = _dist(distribution="discrete", radii=radii.tolist(), fractions=w.tolist(), by=by)
    r = draw_radii(np.random.default_rng(5), dist, N)
    # Then the number fraction of each radius is the target (by mass: f ∝ w / r^3) within
    # 3 binomial standard errors sqrt(f (1 - f) / N) (the stratified counts keep it within 1 / N)
    target = w / radii ** 3 if by == "mass" else w
    target = target / target.sum()
    got = np.array([np.mean(r == x) for x in radii])
    assert np.all(np.abs(got - target) <= 3 * np.sqrt(target * (1 - target) / N))
    if by == "mass":  # and the mass fractions are the requested ones (within 0.5 %)
        mass = np.array([np.sum(r[r == x] ** 3) for x in radii])
        np.testing.assert_allclose(mass / mass.sum(), w, rtol=0.005)


def test_uniform_draws_as_before():
    # Given the old form radius: {min, max} (no distribution key)
    dist = _dist(min=1e-3, max=1.5e-3)
    assert dist.distribution == "uniform"
    # Then its radii are rng.uniform(min, max, n), the draws of the stage before the change
    np.testing.assert_array_equal(draw_radii(np.random.default_rng(6), dist, 50),
                                  np.random.default_rng(6).uniform(1e-3, 1.5e-3, 50))


@pytest.mark.parametrize("planar", [False, True])
def test_draw_amount_reaches_the_amount_within_one_particle_on_the_curve(planar):
    # Given a sieve curve and a target volume (2D: area) of about 1000 particles
    dist = _dist(distribution="sieve", sieves=[2e-3, 4e-3, 8e-3], passing=[0, 50, 100])
    target = 2e-6 if planar else 1e-4  # m^2 or m^3
    r = draw_amount(np.random.default_rng(7), dist, target, planar=planar)
    # Then the drawn amount first reaches the target at the last particle
    v = math.pi * r ** 2 if planar else 4 / 3 * math.pi * r ** 3
    assert v.sum() >= target and v[:-1].sum() < target
    # and (3D) the stratified draw still follows the curve by mass within 1 point at the middle sieve
    if not planar:
        assert sieve_set(2 * r, r ** 3, [4e-3])[0] == pytest.approx(50.0, abs=1.0)


# ---------------------------------------------------------------------------------------
# old configs are bit-identical
# ---------------------------------------------------------------------------------------

# the generate stage's bodies/* and spheres/* arrays of the smoke cases at commit badac01 (before
# sizes and sets existed), written on an AMD EPYC (znver5). Integer arrays must match exactly and
# floats to 1e-12 relative: positions pass through compiled placement arithmetic whose last bits
# depend on the CPU's instructions (the SHA-256 hashes first recorded on a znver2 machine did not
# hold here, while this machine's badac01 output equals HEAD's bit for bit).
OLD = Path(__file__).with_name("data") / "generate_badac01.npz"


@pytest.mark.parametrize("name", ["beads.yaml", "clumps.yaml", "planar.yaml"])
def test_old_cases_generate_the_same_bodies(tmp_path, name):
    run_case(ROOT / "cases" / "smoke" / name, out=tmp_path, only="pour", quiet=True, threads=1)
    old = np.load(OLD)
    keys = sorted(k.split(":", 1)[1] for k in old.files if k.startswith(name + ":"))
    with h5py.File(tmp_path / "00-pour.h5") as f:
        assert sorted(f"{g}/{k}" for g in ("bodies", "spheres") for k in f[g]) == keys
        for key in keys:
            a, b = f[key][()], old[f"{name}:{key}"]
            assert a.dtype == b.dtype and a.shape == b.shape, key
            if a.dtype.kind == "f":
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15, err_msg=key)
            else:
                np.testing.assert_array_equal(a, b, err_msg=key)


# ---------------------------------------------------------------------------------------
# several sets
# ---------------------------------------------------------------------------------------

TWO_SETS = """\
name: two_sets
seed: 3
materials:
  granite: {density: 2650 kg/m^3}
  rubber: {density: 1100 kg/m^3}
stages:
  - name: pour
    type: generate
    region: {shape: box, min: [0, 0, 0], max: [30 mm, 30 mm, 30 mm]}
    sets:
      - {material: granite, count: 40, radius: {distribution: discrete, radii: [1.5 mm, 2 mm], fractions: [0.5, 0.5]}}
      - {material: rubber, volume_fraction: 0.05, radius: {distribution: lognormal, median: 1 mm, gsd: 1.2,
         min: 0.7 mm, max: 1.4 mm}}
      - {material: rubber, count: 10, radius: {min: 1 mm, max: 1.2 mm},
         clump: {spheres: [[-0.5, 0, 0, 0.6], [0.5, 0, 0, 0.6]], resolution: 32}}
"""


def test_two_sets_counts_fractions_materials_and_no_overlap(tmp_path):
    case = tmp_path / "two_sets.yaml"
    case.write_text(TWO_SETS)
    run_case(case, out=tmp_path / "run", quiet=True, threads=1)
    with h5py.File(tmp_path / "run" / "00-pour.h5") as f:
        b = {k: f["bodies"][k][()] for k in f["bodies"]}
        s = {k: f["spheres"][k][()] for k in f["spheres"]}
    sets = b["set"]
    # Then set 0 has its 40 bodies, set 2 its 10 clumps (two spheres each)
    assert np.sum(sets == 0) == 40 and np.sum(sets == 2) == 10
    assert np.all(np.bincount(s["body"])[sets == 2] == 2) and np.all(np.bincount(s["body"])[sets != 2] == 1)
    # and set 1 fills 5 % of the 27 cm^3 box, overshooting by less than one particle
    r1 = s["radius"][sets[s["body"]] == 1]
    v1 = 4 / 3 * math.pi * r1 ** 3
    assert 0.05 * 27e-6 <= v1.sum() < 0.05 * 27e-6 + v1.max()
    # and each sphere has its set's material (granite 0, rubber 1), each body the mass of its density
    np.testing.assert_array_equal(s["material"], np.where(sets[s["body"]] == 0, 0, 1))
    one = np.flatnonzero(sets != 2)
    rho = np.where(sets[one] == 0, 2650.0, 1100.0)
    r_one = s["radius"][np.searchsorted(s["body"], one)]
    np.testing.assert_allclose(b["mass"][one], rho * 4 / 3 * math.pi * r_one ** 3, rtol=1e-12)
    # and no two bodies' bounding spheres overlap (the placement's envelope)
    env = np.array([np.max(np.linalg.norm(s["offset"][s["body"] == i], axis=1) + s["radius"][s["body"] == i])
                    for i in range(len(sets))])
    dist = np.linalg.norm(b["x"][:, None] - b["x"][None], axis=2)
    gap = dist - env[:, None] - env[None]
    np.fill_diagonal(gap, 1.0)
    assert gap.min() >= -1e-12


def test_graded_smoke_case_runs_through_the_cli(tmp_path):
    # Given the shipped smoke case (two sets, each following its sieve curve, two materials)
    result = CliRunner().invoke(cli, ["run", str(ROOT / "cases" / "smoke" / "graded_spheres.yaml"),
                                      "--out", str(tmp_path), "--quiet", "--threads", "1"])
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "01-settle.h5") as f:
        sets, body = f["bodies/set"][()], f["spheres/body"][()]
        mat = f["spheres/material"][()]
    # Then both sets are there after the DEM stage, each with its own material
    assert set(np.unique(sets)) == {0, 1}
    assert set(mat[sets[body] == 0]) == {0} and set(mat[sets[body] == 1]) == {1}
    # and the last snapshot shows each sphere's set beside its material
    import meshio

    snap = meshio.read(sorted((tmp_path / "settle").glob("spheres_*.vtu"))[-1])
    np.testing.assert_array_equal(snap.point_data["set"], sets[body])


# ---------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------

BAD_BASE = """\
name: bad
materials: {glass: {density: 2500 kg/m^3}}
stages:
  - name: pour
    type: generate
    region: {shape: box, min: [0, 0, 0], max: [10 mm, 10 mm, 10 mm]}
"""


@pytest.mark.parametrize("lines, needles", [
    ("    count: 5\n    material: glass\n    radius: {min: 2 mm, max: 1 mm}\n",
     ["case.yaml:9:", "radius.max", "must be >= radius.min"]),
    ("    count: 5\n    material: glass\n    radius: {distribution: lognormal, median: -1 mm, gsd: 1.2}\n",
     ["case.yaml:9:", "radius.median", "must be > 0", "-0.001"]),
    ("    count: 5\n    material: glass\n    radius: {distribution: sieve, sieves: [1 mm, 2 mm, 4 mm],"
     " passing: [0, 60, 50]}\n", ["case.yaml:9:", "radius.passing[2]", "must not decrease", "50"]),
    ("    count: 5\n    material: glass\n    radius: {distribution: sieve, sieves: [1 mm, 2 mm], passing: [10, 100]}\n",
     ["case.yaml:9:", "radius.passing[0]", "must be 0"]),
    ("    count: 5\n    material: glass\n    radius: {distribution: discrete, radii: [1 mm, 2 mm], "
     "fractions: [0.5, 0.6]}\n", ["case.yaml:9:", "radius.fractions", "must sum to 1", "1.1"]),
    ("    count: 5\n    volume_fraction: 0.1\n    material: glass\n    radius: {min: 1 mm, max: 1 mm}\n",
     ["case.yaml:8:", "volume_fraction", "not both", "0.1"]),
    ("    sets:\n      - {material: glass, radius: {min: 1 mm, max: 1 mm}}\n",
     ["case.yaml:8:", "sets[0].count", "required key is missing"]),
])
def test_bad_sizes_exit_2_naming_file_line_key(tmp_path, lines, needles):
    path = tmp_path / "case.yaml"
    path.write_text(BAD_BASE + lines)
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "case.yaml" in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


ADDED = """\
name: added
seed: 4
materials: {glass: {density: 2500 kg/m^3}, steel: {density: 7800 kg/m^3}}
stages:
  - {name: base, type: generate, region: {shape: box, min: [0, 0, 0], max: [20 mm, 20 mm, 10 mm]}, count: 12,
     radius: {min: 1 mm, max: 1 mm}, material: glass}
  - name: top
    type: generate
    add: true
    region: {shape: box, min: [0, 0, 15 mm], max: [20 mm, 20 mm, 25 mm]}
    sets:
      - {material: steel, count: 5, radius: {min: 1 mm, max: 1 mm}}
      - {material: glass, count: 7, radius: {distribution: discrete, radii: [0.8 mm, 1.2 mm], fractions: [0.5, 0.5],
         by: number}}
"""


def test_sets_added_to_a_scene_keep_their_set_and_the_old_bodies_get_minus_one(tmp_path):
    case = tmp_path / "added.yaml"
    case.write_text(ADDED)
    run_case(case, out=tmp_path / "run", quiet=True, threads=1)
    with h5py.File(tmp_path / "run" / "01-top.h5") as f:
        sets, ids = f["bodies/set"][()], f["bodies/id"][()]
    # the 12 old bodies (ids 0-11) are of no set, the added ones of sets 0 (5) and 1 (7)
    assert np.all(sets[ids < 12] == -1)
    assert np.sum(sets == 0) == 5 and np.sum(sets == 1) == 7
