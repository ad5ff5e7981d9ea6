"""Virtual sieving: passing curves, class shares, sieve sizes of spheres, clumps, polygons."""

import numpy as np
import pytest

from demcli.geometry import (
    GeometryError,
    class_shares,
    clump_sieve_size,
    compare_gradation,
    polygon_sieve_size,
    random_polyhedron,
    sieve_set,
    sieve_size,
    sphere_sieve_sizes,
)

SIEVES = np.array([16, 25, 35.5, 45, 56, 63]) * 1e-3  # seed 002, square holes


def test_sieve_set_passing_percent():
    # Given four particles of 10, 20, 30, 40 g with sizes straddling the sieves
    sizes = np.array([0.020, 0.025, 0.050, 0.070])
    masses = np.array([0.010, 0.020, 0.030, 0.040])
    # Then a particle passes when its size is at most the aperture
    passing = sieve_set(sizes, masses, SIEVES)
    assert np.allclose(passing, [0, 30, 30, 30, 60, 60])


@pytest.mark.parametrize("sieves", [[0.02, 0.01], [0.01, 0.01], [], [-1.0, 0.02]])
def test_bad_sieves_are_rejected(sieves):
    with pytest.raises(ValueError, match="sieves"):
        sieve_set([0.01], [1.0], sieves)


def test_bad_particle_sets_are_rejected():
    with pytest.raises(ValueError, match="equal-length"):
        sieve_set([0.01, 0.02], [1.0], SIEVES)
    with pytest.raises(ValueError, match="masses"):
        sieve_set([0.01], [0.0], SIEVES)


def test_seed_002_wide_gradation_class_shares():
    # Given the seed's wide gradation 0/0/4/33/79/95 % passing at 16 ... 63 mm
    shares = class_shares(SIEVES, [0, 0, 4, 33, 79, 95])
    # Then P_0 = Q_1, P_j = Q_j+1 - Q_j, P_6 = 100 - Q_6
    assert np.allclose(shares, [0, 0, 4, 29, 46, 16, 5])
    with pytest.raises(ValueError, match="non-decreasing"):
        class_shares(SIEVES, [0, 0, 40, 33, 79, 95])
    with pytest.raises(ValueError, match="one value per sieve"):
        class_shares(SIEVES, [0, 100])


def test_compare_gradation_table():
    table = compare_gradation(SIEVES, [0, 0, 4, 33, 79, 95], [0, 1, 5, 30, 80, 95])
    assert np.allclose(table.target, [0, 0, 4, 29, 46, 16, 5])
    assert np.allclose(table.achieved, [0, 1, 4, 25, 50, 15, 5])
    assert np.allclose(table.difference, [0, 1, 0, -4, 4, -1, 0])
    rows = table.rows()
    assert len(rows) == 7 and rows[0]["lower_m"] == 0.0 and rows[-1]["upper_m"] == np.inf
    assert rows[3] == pytest.approx(dict(lower_m=0.0355, upper_m=0.045, target_pct=29.0, achieved_pct=25.0,
                                         difference_pct=-4.0))


def test_polyhedron_set_round_trip():
    # Given random polyhedra sieved one by one, the set's curve counts exactly those passing
    rng = np.random.default_rng(9)
    polys = [random_polyhedron(rng, 14, rng.uniform(0.005, 0.04, 3)) for _ in range(30)]
    sizes = np.array([sieve_size(p) for p in polys])
    masses = 2600.0 * np.array([p.volume for p in polys])
    passing = sieve_set(sizes, masses, SIEVES)
    for a, q in zip(SIEVES, passing):
        assert np.isclose(q, 100.0 * masses[sizes <= a].sum() / masses.sum())


def test_spheres_and_clumps():
    assert np.allclose(sphere_sieve_sizes([0.01, 0.02]), [0.02, 0.04])
    # a one-sphere clump: the sampled hull lies inside the sphere (0.6 % low at 256 samples)
    d = clump_sieve_size([[1.0, 2.0, 3.0]], [0.01])
    assert 0.99 * 0.02 < d <= 0.02
    # two overlapping spheres (a capsule-like hull): the least shadow is the disc
    # seen along the axis, so the sieve size is still the diameter
    d2 = clump_sieve_size([[0, 0, 0], [0.015, 0.0, 0.0]], [0.01, 0.01], n_samples=128)
    assert 0.98 * 0.02 < d2 <= 0.02 * (1 + 1e-9)  # 1.4 % low at 128 samples
    with pytest.raises(GeometryError):
        clump_sieve_size([[0, 0, 0]], [0.0])


def test_polygon_sieve_size():
    square = np.array([[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]])
    assert np.isclose(polygon_sieve_size(square), 0.04)
    plate = np.array([[0, 0], [0.064, 0], [0.064, 0.004], [0, 0.004]]) @ [[0.6, 0.8], [-0.8, 0.6]]
    assert np.isclose(polygon_sieve_size(plate), 0.068 / np.sqrt(2.0))
    with pytest.raises(GeometryError, match="collinear"):
        polygon_sieve_size([[0, 0], [1, 1], [2, 2]])
    with pytest.raises(GeometryError, match="3 distinct"):
        polygon_sieve_size([[0, 0], [0, 0], [1, 1]])
