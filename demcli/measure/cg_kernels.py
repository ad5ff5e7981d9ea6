"""Coarse-graining kernels (Goldhirsch 2010; Weinhart, Thornton, Luding & Bokhove 2012, as in
MercuryCG): the fields of point masses and contact forces smoothed by a kernel phi on a grid.

Kernels of width w, normalised (their integral over space is 1):

* Gaussian of standard deviation w cut at R = 3 w: phi(r) = exp(-r^2 / (2 w^2)) / ((2 pi)^(3/2)
  w^3 C) for r < R, with C = erf(3 / sqrt 2) - 3 sqrt(2 / pi) exp(-9/2) = 0.97071 its share inside
  R (the cut kernel's variance along an axis is 0.918 w^2);
* Lucy (Lucy 1977) of cutoff c = 2 sqrt(3) w: phi(r) = 105 / (16 pi c^3) (1 + 3 r/c)(1 - r/c)^3
  for r < c (its variance along an axis <r^2> / 3 = c^2 / 12 = w^2).

On a lattice of spacing d the smoothed density ripples: by +-1.6 % with the Gaussian at w = d
(the step of the cut at 3 w), 0.2 % at w = 2 d; by 0.03 % with Lucy at w = d (measured on a
simple cubic lattice: tests/measure/test_coarse.py). Lucy is the better choice for w ~ d.

The loops are serial, bodies and segments in their given order: the sums are the same on any
number of threads.
"""

import math

import numpy as np

from demcli.jit import njit

GAUSSIAN = 0
LUCY = 1
KERNELS = {"gaussian": GAUSSIAN, "lucy": LUCY}
GAUSS_SHARE = math.erf(3.0 / math.sqrt(2.0)) - 3.0 * math.sqrt(2.0 / math.pi) * math.exp(-4.5)
LUCY_RATIO = 2.0 * math.sqrt(3.0)
_GL_S, _GL_W = np.polynomial.legendre.leggauss(8)  # 8-point Gauss-Legendre on [-1, 1]


@njit
def cutoff(w, kind):
    """The kernel's range R [m] for width w [m]: 3 w (Gaussian), 2 sqrt(3) w (Lucy)."""
    return 3.0 * w if kind == GAUSSIAN else LUCY_RATIO * w


@njit
def phi(r2, w, kind):
    """The kernel phi [1/m^3] at squared distance r2 [m^2] for width w [m]; 0 beyond the cutoff."""
    big = cutoff(w, kind)
    if r2 >= big * big:
        return 0.0
    if kind == GAUSSIAN:
        return math.exp(-0.5 * r2 / (w * w)) / ((2.0 * math.pi) ** 1.5 * w ** 3 * GAUSS_SHARE)
    u = math.sqrt(r2) / big
    return 105.0 / (16.0 * math.pi * big ** 3) * (1.0 + 3.0 * u) * (1.0 - u) ** 3


@njit
def line_integral(ex, ey, ez, dx, dy, dz, w, kind):
    """int_0^1 phi(|e - s d|) ds [1/m^3]: the kernel at a grid point averaged along the segment
    from a to a + d, e = point - a [m]. The integral runs over the part of the segment inside the
    cutoff sphere only (its ends solved exactly), in closed form for the Gaussian (erf) and by
    8-point Gauss-Legendre for Lucy (smooth inside the cutoff)."""
    big = cutoff(w, kind)
    dd = dx * dx + dy * dy + dz * dz
    ee = ex * ex + ey * ey + ez * ez
    if dd <= 1e-24 * (ee + big * big):
        return phi(ee, w, kind)
    ed = ex * dx + ey * dy + ez * dz
    sm = ed / dd
    h2 = max(ee - ed * sm, 0.0)
    if h2 >= big * big:
        return 0.0
    half = math.sqrt((big * big - h2) / dd)
    s0 = max(0.0, sm - half)
    s1 = min(1.0, sm + half)
    if s1 <= s0:
        return 0.0
    if kind == GAUSSIAN:
        ln = math.sqrt(dd)
        k = ln / (math.sqrt(2.0) * w)
        norm = 1.0 / ((2.0 * math.pi) ** 1.5 * w ** 3 * GAUSS_SHARE)
        return norm * math.exp(-0.5 * h2 / (w * w)) * (math.erf((s1 - sm) * k) - math.erf((s0 - sm) * k)) \
            * math.sqrt(math.pi) / (2.0 * k)
    total = 0.0
    for q in range(_GL_S.shape[0]):
        s = s0 + 0.5 * (s1 - s0) * (_GL_S[q] + 1.0)
        qx, qy, qz = ex - s * dx, ey - s * dy, ez - s * dz
        total += _GL_W[q] * phi(qx * qx + qy * qy + qz * qz, w, kind)
    return 0.5 * (s1 - s0) * total


@njit
def _span(c, reach, lo, h, n):
    """(first, last + 1) grid indices along one axis within ``reach`` of coordinate c."""
    first = max(0, int(math.ceil((c - reach - lo) / h)))
    last = min(n - 1, int(math.floor((c + reach - lo) / h)))
    return first, last + 1


@njit
def point_fields(lo, h, shape, x, m, v, w, kind):
    """Sums over the bodies at every grid point r: density sum m phi [kg/m^3], momentum
    sum m v phi [kg/(m^2 s)] and sum m v (x) v phi [Pa], with phi = phi(r - x_b).

    Args: lo (3,) grid origin [m]; h (3,) spacing [m]; shape (3,) int points per axis (x
    fastest: point i + nx (j + ny k)); x (n, 3) [m], m (n,) [kg], v (n, 3) [m/s] of the bodies;
    w kernel width [m]; kind GAUSSIAN or LUCY. Returns (rho (p,), mom (p, 3), mvv (p, 9)).
    """
    nx, ny, nz = shape[0], shape[1], shape[2]
    rho = np.zeros(nx * ny * nz)
    mom = np.zeros((nx * ny * nz, 3))
    mvv = np.zeros((nx * ny * nz, 9))
    big = cutoff(w, kind)
    for b in range(x.shape[0]):
        i0, i1 = _span(x[b, 0], big, lo[0], h[0], nx)
        j0, j1 = _span(x[b, 1], big, lo[1], h[1], ny)
        k0, k1 = _span(x[b, 2], big, lo[2], h[2], nz)
        for k in range(k0, k1):
            for j in range(j0, j1):
                for i in range(i0, i1):
                    rx = lo[0] + i * h[0] - x[b, 0]
                    ry = lo[1] + j * h[1] - x[b, 1]
                    rz = lo[2] + k * h[2] - x[b, 2]
                    p = phi(rx * rx + ry * ry + rz * rz, w, kind)
                    if p == 0.0:
                        continue
                    g = i + nx * (j + ny * k)
                    rho[g] += m[b] * p
                    for a in range(3):
                        mom[g, a] += m[b] * v[b, a] * p
                        for c in range(3):
                            mvv[g, 3 * a + c] += m[b] * v[b, a] * v[b, c] * p
    return rho, mom, mvv


@njit
def contact_stress(lo, h, shape, start, end, force, w, kind):
    """Contact stress [Pa] at every grid point, compression positive (p, 9), row-major (i, j):

        sigma_ij(r) = sum_s (a_s - c_s)_i f_s,j int_0^1 phi(r - a_s - t (c_s - a_s)) dt

    over the body sides s of the contacts: the segment from the body's centre a_s [m] (``start``,
    (m, 3)) to the contact point c_s (``end``) and the force f_s [N] on the body (``force``). A pair
    is two sides, together the whole branch line between the two centres (Weinhart et al. 2012
    eq. 29); a wall contact one side. Integrated over space it is the Love-Weber sum.
    """
    nx, ny, nz = shape[0], shape[1], shape[2]
    out = np.zeros((nx * ny * nz, 9))
    big = cutoff(w, kind)
    for s in range(start.shape[0]):
        dx, dy, dz = end[s, 0] - start[s, 0], end[s, 1] - start[s, 1], end[s, 2] - start[s, 2]
        i0, i1 = _span(start[s, 0] + 0.5 * dx, big + 0.5 * abs(dx), lo[0], h[0], nx)
        j0, j1 = _span(start[s, 1] + 0.5 * dy, big + 0.5 * abs(dy), lo[1], h[1], ny)
        k0, k1 = _span(start[s, 2] + 0.5 * dz, big + 0.5 * abs(dz), lo[2], h[2], nz)
        for k in range(k0, k1):
            for j in range(j0, j1):
                for i in range(i0, i1):
                    p = line_integral(lo[0] + i * h[0] - start[s, 0], lo[1] + j * h[1] - start[s, 1],
                                      lo[2] + k * h[2] - start[s, 2], dx, dy, dz, w, kind)
                    if p == 0.0:
                        continue
                    g = i + nx * (j + ny * k)
                    out[g, 0] -= dx * force[s, 0] * p
                    out[g, 1] -= dx * force[s, 1] * p
                    out[g, 2] -= dx * force[s, 2] * p
                    out[g, 3] -= dy * force[s, 0] * p
                    out[g, 4] -= dy * force[s, 1] * p
                    out[g, 5] -= dy * force[s, 2] * p
                    out[g, 6] -= dz * force[s, 0] * p
                    out[g, 7] -= dz * force[s, 1] * p
                    out[g, 8] -= dz * force[s, 2] * p
    return out
