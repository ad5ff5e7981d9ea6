"""Coarse-grained fields (issue #33 item 3): the kernels against their closed forms and brute-force
quadrature, the density of a uniform packing, and the vertical stress of a column at rest under
gravity against rho_bulk g depth."""

import math

import numpy as np
import pytest

from demcli.measure.cg_kernels import GAUSSIAN, LUCY, cutoff, line_integral, phi
from demcli.measure.coarse import Grid, coarse_fields, make_grid


def _gauss_cut_variance():
    """Variance along an axis of the unit Gaussian cut at r = 3: int_0^3 r^4 e^(-r^2/2) dr sqrt(2/pi)
    / (3 C), by parts from int_0^3 r^2 e^(-r^2/2) dr = sqrt(pi/2) erf(3/sqrt 2) - 3 e^(-9/2)."""
    i2 = math.sqrt(math.pi / 2) * math.erf(3 / math.sqrt(2)) - 3 * math.exp(-4.5)
    share = math.erf(3 / math.sqrt(2)) - 3 * math.sqrt(2 / math.pi) * math.exp(-4.5)
    return (3 * i2 - 27 * math.exp(-4.5)) * math.sqrt(2 / math.pi) / (3 * share)


@pytest.mark.parametrize("kind", [GAUSSIAN, LUCY])
def test_each_kernel_integrates_to_one_with_its_variance(kind):
    # Given w = 1 and a cubic grid h = w / 8 covering the cutoff sphere
    w, h = 1.0, 0.125
    big = cutoff(w, kind)
    g = np.arange(-big, big + h / 2, h)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    r2 = (x * x + y * y + z * z).ravel()
    vals = np.array([phi(v, w, kind) for v in r2])
    # Then sum phi h^3 = 1 and sum phi x^2 h^3 = w^2 (Lucy) or 0.918 w^2 (the cut Gaussian), to the
    # midpoint rule's error (< 2e-3)
    assert np.sum(vals) * h ** 3 == pytest.approx(1.0, abs=2e-3)
    variance = w * w * (_gauss_cut_variance() if kind == GAUSSIAN else 1.0)
    assert np.sum(vals * x.ravel() ** 2) * h ** 3 == pytest.approx(variance, rel=2e-3)


def _phi_ref(r2, w, kind):
    """The kernels written out again in numpy (module doc of demcli.measure.cg_kernels)."""
    r = np.sqrt(r2)
    if kind == GAUSSIAN:
        share = math.erf(3 / math.sqrt(2)) - 3 * math.sqrt(2 / math.pi) * math.exp(-4.5)
        return np.where(r < 3 * w, np.exp(-r2 / (2 * w * w)) / ((2 * math.pi) ** 1.5 * w ** 3 * share), 0.0)
    c = 2 * math.sqrt(3) * w
    u = np.minimum(r / c, 1.0)
    return 105 / (16 * math.pi * c ** 3) * (1 + 3 * u) * (1 - u) ** 3


@pytest.mark.parametrize("kind", [GAUSSIAN, LUCY])
def test_the_line_integral_matches_quadrature_along_the_segment(kind):
    # Given random segments and points (some segments crossing the cutoff, some outside it)
    rng = np.random.default_rng(3)
    w = 0.7
    s = (np.arange(20000) + 0.5) / 20000
    assert _phi_ref(0.3, w, kind) == pytest.approx(phi(0.3, w, kind), rel=1e-14)
    for _ in range(60):
        e = rng.uniform(-2.5, 2.5, 3)
        d = rng.uniform(-1.5, 1.5, 3)
        q = e[None, :] - s[:, None] * d[None, :]
        ref = float(np.mean(_phi_ref(np.einsum("ij,ij->i", q, q), w, kind)))
        # Then the closed form (Gaussian) and Gauss-Legendre on the clipped part (Lucy) agree with a
        # 20 000-point midpoint rule to 1e-5 of the kernel's peak
        got = line_integral(e[0], e[1], e[2], d[0], d[1], d[2], w, kind)
        assert abs(got - ref) < 1e-5 * phi(0.0, w, kind), (e, d, got, ref)
    # a segment of zero length is the kernel at the point
    assert line_integral(0.3, 0.2, 0.1, 0.0, 0.0, 0.0, w, kind) == phi(0.14, w, kind)


def _block(n_xy, n_z, d):
    """A simple cubic lattice n_xy x n_xy x n_z of spheres of diameter d resting on a floor at z = 0."""
    g = (np.arange(n_xy) + 0.5) * d
    h = (np.arange(n_z) + 0.5) * d
    x, y, z = np.meshgrid(g, g, h, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


# (kernel, width / d, the lattice's density ripple: measured +-0.18 % and +-0.03 %)
KERNELS = [("gaussian", 2.0, 3e-3), ("lucy", 1.0, 5e-4)]


@pytest.mark.parametrize("kernel, width, ripple", KERNELS)
def test_a_uniform_packing_has_the_bulk_density_away_from_its_boundaries(kernel, width, ripple):
    # Given a 16^3 simple cubic lattice (d = 1 mm, sphere mass m): bulk density m / d^3
    d, m = 1e-3, 2e-6
    x = _block(16, 16, d)
    grid = make_grid((6.5 * d,) * 3, (9.5 * d,) * 3, 0.5 * d)
    f = coarse_fields(grid, x, np.full(len(x), m), np.zeros_like(x), np.zeros((0, 3)), np.zeros((0, 3)),
                      np.zeros((0, 3)), width * d, kernel)
    # Then the coarse-grained density at points more than the cutoff from the boundary is m / d^3 to
    # the lattice's ripple, the velocity and the stress are 0
    assert np.allclose(f["density"], m / d ** 3, rtol=ripple, atol=0), (f["density"].min(), f["density"].max())
    assert not f["velocity"].any() and not f["stress"].any()


def _column_contacts(x, d, weight, n_z):
    """Sides (start, end, force on the body) of the contacts of a lattice at rest under gravity:
    each vertical pair carries the weight of the spheres above, the floor the whole column."""
    start, end, force = [], [], []
    for b, p in enumerate(x):
        above = n_z - 1 - int(round(p[2] / d - 0.5))
        # the contact above b (if any) pushes it down with the weight of the spheres above
        if above > 0:
            start.append(p), end.append(p + [0, 0, d / 2]), force.append([0, 0, -above * weight])
        # the contact below (a sphere, or the floor) pushes it up with its weight and those above
        start.append(p), end.append(p - [0, 0, d / 2]), force.append([0, 0, (above + 1) * weight])
    return np.array(start), np.array(end), np.array(force)


@pytest.mark.parametrize("kernel, width, ripple", KERNELS)
def test_the_vertical_stress_of_a_column_at_rest_rises_linearly_with_depth(kernel, width, ripple):
    # Given a lattice 14 x 14 x 24 spheres (d = 2 mm, mass m) at rest on a floor under gravity g,
    # each contact carrying the weight above it: rho_bulk = m / d^3
    d, m, g = 2e-3, 1e-5, 9.81
    n_xy, n_z = 14, 24
    x = _block(n_xy, n_z, d)
    start, end, force = _column_contacts(x, d, m * g, n_z)
    w = width * d
    reach = cutoff(w, 0 if kernel == "gaussian" else 1)
    # grid points along the axis of the block, the kernel's cutoff from every surface
    z = np.arange(reach + 0.5 * d, n_z * d - reach, 0.25 * d)
    grid = Grid(np.array([7 * d, 7 * d, z[0]]), np.array([d, d, 0.25 * d]), np.array([1, 1, len(z)]))
    f = coarse_fields(grid, x, np.full(len(x), m), np.zeros_like(x), start, end, force, w, kernel)
    depth = n_z * d - z
    expected = m / d ** 3 * g * depth
    sigma = f["stress"].reshape(-1, 3, 3)
    # Then sigma_zz = rho_bulk g depth (compression positive) to the lattice's ripple, the other
    # components vanish (no lateral forces), and the density is the bulk density
    assert np.allclose(sigma[:, 2, 2], expected, rtol=ripple, atol=0), sigma[:, 2, 2] / expected - 1
    assert np.abs(sigma[:, :2, :]).max() < 1e-12 * expected.max()
    assert np.allclose(f["density"], m / d ** 3, rtol=ripple, atol=0)
    # And summed over space (a grid covering everything) the contact stress is the Love-Weber sum
    big = 4 * w
    full = make_grid((-big, -big, -big), (n_xy * d + big, n_xy * d + big, n_z * d + big), 0.5 * w)
    total = coarse_fields(full, x, np.full(len(x), m), np.zeros_like(x), start, end, force, w, kernel)
    love = -np.einsum("ki,kj->ij", end - start, force)
    integral = total["contact_stress"].sum(axis=0).reshape(3, 3) * np.prod(full.spacing)
    assert integral[2, 2] == pytest.approx(love[2, 2], rel=1e-3)


def test_moving_bodies_carry_momentum_and_kinetic_stress():
    # Given a uniform lattice whose spheres move with u = (1, 0, 0) m/s plus +-0.1 m/s along z, alternating
    # from each sphere to its six neighbours
    d, m = 1e-3, 2e-6
    x = _block(12, 12, d)
    v = np.zeros_like(x)
    v[:, 0] = 1.0
    v[:, 2] = np.where(np.sum(np.round(x / d - 0.5), axis=1) % 2 == 0, 0.1, -0.1)
    grid = make_grid((5.5 * d,) * 3, (6.5 * d,) * 3, 0.5 * d)
    f = coarse_fields(grid, x, np.full(len(x), m), v, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), d, "lucy")
    rho = m / d ** 3
    # Then the velocity is the mean u (the alternation smoothed out to 0.2 % of its amplitude), the
    # momentum rho u, and the kinetic stress (compression positive) rho <v'v'> = rho 0.01 m^2/s^2
    # along zz, 0 along xx
    assert np.allclose(f["velocity"][:, 0], 1.0, rtol=1e-12) and np.allclose(f["velocity"][:, 2], 0.0, atol=2e-4)
    assert np.allclose(f["momentum"][:, 0], rho, rtol=5e-4)
    k = f["kinetic_stress"].reshape(-1, 3, 3)
    assert np.allclose(k[:, 2, 2], rho * 0.01, rtol=1e-3) and np.abs(k[:, 0, 0]).max() < 1e-9 * rho
    assert math.isclose(float(f["pressure"][0]), float(np.trace(k[0])) / 3, rel_tol=1e-12)
