"""Periodic cell (docs/periodic.md): minimum image, pressure of a lattice, boundary pairs, the servo."""

import itertools

import numpy as np
import pytest

from demcli.engine.periodic_cell import deviator, make_cell
from demcli.kernels import layout as K


@pytest.fixture
def lattice(build):
    """A simple cubic lattice of spacing a [m] with each contact overlapping by delta [m], n_x x n_y x
    n_z spheres filling a periodic cell of n a per axis (linear springs k_n [N/m], no friction)."""
    def make(counts=(3, 4, 5), a=0.01, delta=1e-5, kn=1e5):
        B = build
        g = [np.arange(n) * a + 0.5 * a for n in counts]
        x = np.array(list(itertools.product(*g)))
        mats = [B.Material("m", 2500.0, restitution=0.5)]
        s = B.sphere_system(x, np.zeros_like(x), 0.5 * (a + delta), mats, B.ContactModel(law="linear", kn=kn),
                            dt_factor=0.1)
        s.cell = make_cell(np.array(counts, float) * a)
        return s
    return make


def _stress(s):
    return s.cell[K.C_STRESS:K.C_STRESS + 6]


def test_simple_cubic_lattice_pressure_is_analytic(lattice):
    # Given a simple cubic lattice (z = 6 contacts per sphere, branch a, overlap delta, linear
    # springs) filling a periodic cell: every sphere touches its images across the faces
    a, delta, kn = 0.01, 1e-5, 1e5
    s = lattice(a=a, delta=delta, kn=kn)
    # When the loads are evaluated at rest (the stage's step-0 evaluation)
    s.advance(0)
    # Then each normal stress is the Love-Weber sum k delta a / a^3 per sphere, the shear stresses
    # vanish, and p = z k delta a / (6 a^3) = k delta / a^2 (every contact counted, 3 per sphere)
    p_exact = kn * delta / a ** 2
    sig = _stress(s)
    assert int(s.nl.act.sum()) == 3 * len(s.x)
    np.testing.assert_allclose(sig[:3], p_exact, rtol=1e-9)
    assert np.all(np.abs(sig[3:]) <= 1e-9 * p_exact)
    p, q = deviator(sig)
    assert abs(p - p_exact) <= 1e-9 * p_exact and q <= 1e-9 * p_exact
    # and every sphere is in equilibrium (its six forces cancel)
    assert np.abs(s.f).max() <= 1e-9 * kn * delta


def test_affinely_compressed_lattice_follows_the_spring_and_the_mean_flow_dashpot(build):
    # Given the simple cubic lattice with linear springs k_n and an absolute dashpot c_n, the cell
    # compressed at a constant strain rate edot < 0 on every axis (no servo)
    a0, r, kn, cn, edot = 0.01, 0.5 * (0.01 + 1e-5), 1e5, 2.0, -5.0
    counts = (3, 4, 5)
    g = [np.arange(n) * a0 + 0.5 * a0 for n in counts]
    x = np.array(list(itertools.product(*g)))
    mats = [build.Material("m", 2500.0)]
    s = build.sphere_system(x, np.zeros_like(x), r, mats, build.ContactModel(law="linear", kn=kn, cn=cn),
                            dt_factor=0.1)
    s.cell = make_cell(np.array(counts, float) * a0, rate=(edot,) * 3)
    # When it is stepped (by symmetry every sphere follows the mean flow: its fluctuation stays 0)
    n = 300
    s.advance(n)
    # Then the cell shrank by (1 + edot dt)^n, and the pressure is that of the lattice at the new
    # spacing a: each contact carries k_n (2 r - a) from the spring plus c_n (-edot a) from the
    # dashpot, the relative velocity of the mean flow across its branch: p = (k_n (2 r - a) - c_n edot a) / a^2
    scale = (1.0 + edot * s.dt) ** n
    lengths = s.cell[K.C_L:K.C_L + 3]
    np.testing.assert_allclose(lengths, np.array(counts) * a0 * scale, rtol=1e-12)
    a = a0 * scale
    p_exact = (kn * (2 * r - a) - cn * edot * a) / a ** 2
    sig = _stress(s)
    np.testing.assert_allclose(sig[:3], p_exact, rtol=1e-9)
    assert cn * -edot * a > 1e-4 * kn * (2 * r - a)  # without the mean-flow dashpot p would be off by > 1e-4
    assert np.abs(s.v).max() <= 1e-9 * -edot * a


def _pair(build, x, v, cell_lengths):
    B = build
    mats = [B.Material("m", 2500.0, friction=0.5, restitution=0.5)]
    s = B.sphere_system(x, v, 0.005, mats, B.ContactModel(law="linear", kn=1e5, kt=2e4), effects=["friction"],
                        dt_factor=0.05)
    s.cell = None if cell_lengths is None else make_cell(np.asarray(cell_lengths, float))
    return s


def test_a_pair_across_the_boundary_moves_as_the_same_pair_inside(build):
    # Given two overlapping spheres with a sliding relative velocity, once inside the cell and
    # once split across its x faces (the same branch vector through the minimum image)
    L = np.array([0.05, 0.04, 0.045])
    inside = np.array([[0.02, 0.02, 0.02], [0.0295, 0.021, 0.0205]])
    across = inside.copy()
    across[:, 0] += 0.0251  # sphere 1 passes x = L_x, sphere 0 does not
    across[:, 0] -= L[0] * np.floor(across[:, 0] / L[0])
    assert across[1, 0] < across[0, 0]
    v = np.array([[0.0, 0.01, 0.0], [0.0, -0.01, 0.002]])
    a = _pair(build, inside, v, L)
    b = _pair(build, across, v, L)
    # When both are stepped, step by step
    touched = slid = False
    for _ in range(60):
        for s in (a, b):
            s.advance(1)
        # Then forces, velocities, spins and the tangential spring agree to round-off of the image shift
        for name in ("f", "v", "w"):
            ref = getattr(a, name)
            np.testing.assert_allclose(getattr(b, name), ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max() + 1e-300)
        np.testing.assert_allclose(b.nl.ft, a.nl.ft, rtol=1e-9, atol=1e-9 * np.abs(a.nl.ft).max() + 1e-300)
        touched |= bool(np.abs(a.f).max() > 0.0)
        slid |= bool(np.abs(a.nl.ft).max() > 0.0)
    assert touched and slid


def _brute_pairs(x, rad, skin, lengths):
    out = set()
    for i in range(len(x)):
        for j in range(i + 1, len(x)):
            best = np.inf
            for shift in itertools.product((-1, 0, 1), repeat=3):
                best = min(best, np.linalg.norm(x[i] - x[j] + np.array(shift) * lengths))
            if best < rad[i] + rad[j] + skin:
                out.add((i, j))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_minimum_image_pairs_equal_a_brute_force_over_the_27_images(seed):
    from demcli.kernels.neighbors import build_pairs

    # Given random spheres in a random orthorhombic cell (some axes only 1 or 2 grid cells long)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 120))
    rad = rng.uniform(0.5, 1.0, n) * 1e-3
    skin = 0.3e-3
    lengths = rng.uniform(2.0 * (2e-3 + skin) * 1.01, 15e-3, 3)
    x = rng.uniform(0.0, 1.0, (n, 3)) * lengths
    cell = make_cell(lengths)
    # When the Verlet list is built through the periodic grid
    start, pi, pj = build_pairs(x, rad, np.arange(n, dtype=np.int64), skin, max(64, 8 * n), cell)
    # Then it holds exactly the pairs whose nearest image is within r_i + r_j + skin, each once
    got = list(zip(pi.tolist(), pj.tolist()))
    assert len(got) == len(set(got))
    assert set(got) == _brute_pairs(x, rad, skin, lengths)


def test_servo_brings_a_loose_cell_to_the_target_pressure(build):
    # Given 200 loose spheres (no contacts) in a periodic cell, all three axes servo-controlled
    rng = np.random.default_rng(4)
    n = 200
    r = rng.uniform(0.8, 1.2, n) * 1e-3
    L = 0.02
    x = rng.uniform(0, L, (n, 3))
    B = build
    mats = [B.Material("m", 2500.0, young=1e8, poisson=0.25, friction=0.3, restitution=0.3)]
    s = B.sphere_system(x, np.zeros((n, 3)), r, mats, B.ContactModel(), effects=["friction", "local_damping"],
                        dt_factor=0.2, local_damping=0.3)
    target = 2e4
    s.cell = make_cell(np.array([L, L, L]), stress=(target,) * 3, gain=0.02, max_rate=50.0)
    # When it is stepped (wrapped into the cell at the first list build)
    p_hist = []
    for _ in range(60):
        s.advance(500)
        p_hist.append(deviator(_stress(s))[0])
    # Then the pressure settles at the target within 2 % (mean of the last 10 chunks) and no axis runs away
    assert abs(np.mean(p_hist[-10:]) - target) <= 0.02 * target, p_hist[-10:]
    assert np.all(s.x >= -s.skin) and np.all(s.x < s.cell[K.C_L:K.C_L + 3] + s.skin)
