"""Periodic orthorhombic cell of a sphere scene: minimum image, affine deformation, stress and servo.

The cell is [0, L_x) x [0, L_y) x [0, L_z) [m]. A scene without one passes ``cell=None`` and
every function here is then the identity or nothing, decided at compile time by the type of
``cell`` (:mod:`demcli.kernels.switch`): a non-periodic scene compiles and runs exactly as
before. With a cell, ``cell`` is one float64 array of the C_* slots below (docs/periodic.md):

* minimum image of a branch vector b = x_i - x_j: b_d <- b_d - L_d round(b_d / L_d) [m]
  (valid while every L_d > 2 (2 r_max + skin): one image at most within reach);
* affine deformation per step of dt [s]: L_d <- L_d (1 + edot_d dt), x_d <- x_d (1 + edot_d dt)
  (strain rate edot_d [1/s], about the cell origin); velocities are the fluctuations about the
  mean flow v_mean = edot . x, so a contact sees the relative velocity
  v_i - v_j + edot . b [m/s];
* Love-Weber stress, compression positive [Pa]:
  sigma_ab = (sum_contacts f_a b_b + sum_spheres m v_a v_b) / V, V = L_x L_y L_z [m^3],
  f the force on i [N], b the minimum-image branch x_i - x_j [m], v the fluctuation [m/s];
* servo per stress-controlled axis: edot_d = clip(beta (sigma_dd - target_d) / (K_d dt), +-edot_max),
  K_d = sum_contacts k_n n_d^2 b_d^2 / V [Pa] the affine stiffness of the contacts, k_n the
  tangent normal stiffness [N/m]; edot_max when no contact carries load.
"""

import math

import numpy as np
from numba import types
from numba.extending import overload

from demcli.jit import njit
from demcli.kernels.contact import HERTZ, P_ESTAR, P_KN
from demcli.kernels.layout import (C_GAIN, C_L, C_MAX_RATE, C_MODE, C_RATE, C_STIFF, C_STRESS, C_TARGET,
                                   RATE)

_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _none(t):
    return isinstance(t, types.NoneType)


# ---- minimum image -------------------------------------------------------------------
@njit(inline="always")
def _image(cell, dx, dy, dz):
    lx = cell[C_L]
    ly = cell[C_L + 1]
    lz = cell[C_L + 2]
    return (dx - lx * math.floor(dx / lx + 0.5), dy - ly * math.floor(dy / ly + 0.5),
            dz - lz * math.floor(dz / lz + 0.5))


def min_image(cell, dx, dy, dz):
    """Minimum-image branch vector [m] (no cell: unchanged; plain Python with NUMBA_DISABLE_JIT=1)."""
    return (dx, dy, dz) if cell is None else _image(cell, dx, dy, dz)


@overload(min_image, inline="always")
def _min_image(cell, dx, dy, dz):
    if _none(cell):
        return lambda cell, dx, dy, dz: (dx, dy, dz)
    return lambda cell, dx, dy, dz: _image(cell, dx, dy, dz)


def mean_flow(cell, vx, vy, vz, dx, dy, dz):
    """Relative velocity [m/s] plus the mean flow's edot . b across branch b [m] (no cell: unchanged)."""
    if cell is None:
        return vx, vy, vz
    return vx + cell[C_RATE] * dx, vy + cell[C_RATE + 1] * dy, vz + cell[C_RATE + 2] * dz


@overload(mean_flow, inline="always")
def _mean_flow(cell, vx, vy, vz, dx, dy, dz):
    if _none(cell):
        return lambda cell, vx, vy, vz, dx, dy, dz: (vx, vy, vz)
    return lambda cell, vx, vy, vz, dx, dy, dz: (vx + cell[C_RATE] * dx, vy + cell[C_RATE + 1] * dy,
                                                 vz + cell[C_RATE + 2] * dz)


# ---- the cell grid of the neighbour search ------------------------------------------
def grid_cells(cell, d, lo, hi, h):
    """Cells of the search grid along axis d (float): the points' span (hi - lo) / h + 1, or
    floor(L_d / h) >= 1 over a periodic cell (its last cell the wider)."""
    if cell is None:
        span = (hi[d] - lo[d]) / h
        return (math.floor(span) + 1.0) if span < 1e18 else 1e18
    return max(math.floor(cell[C_L + d] / h), 1.0)


@overload(grid_cells)
def _grid_cells(cell, d, lo, hi, h):
    if _none(cell):
        def count(cell, d, lo, hi, h):
            span = (hi[d] - lo[d]) / h
            return (math.floor(span) + 1.0) if span < 1e18 else 1e18
        return count
    return lambda cell, d, lo, hi, h: max(math.floor(cell[C_L + d] / h), 1.0)


def grid_origin(cell, lo):
    """The grid's low corner: the points' (no cell) or the cell's origin 0."""
    if cell is not None:
        lo[:] = 0.0


@overload(grid_origin, inline="always")
def _grid_origin(cell, lo):
    if _none(cell):
        return lambda cell, lo: None

    def origin(cell, lo):
        lo[:] = 0.0
    return origin


def window(c, n, cell):
    """Range of neighbour cells (k0, k1) of cell c along an axis of n cells: clamped to the grid
    (no cell), or c-1..c+1 around the periodic axis (all n when n < 3: no cell twice)."""
    if cell is None:
        return max(c - 1, 0), min(c + 2, n)
    return (c - 1, c + 2) if n >= 3 else (0, n)


@overload(window, inline="always")
def _window(c, n, cell):
    if _none(cell):
        return lambda c, n, cell: (max(c - 1, 0), min(c + 2, n))
    def wrapped(c, n, cell):
        big = min(n // 3, 1)  # 1 when n >= 3: arithmetic, an inlined conditional trips numba's IR checks
        return big * (c - 1), big * (c + 2) + (1 - big) * n
    return wrapped


def wrap_index(k, n, cell):
    """Cell index k on an axis of n cells: as it is (no cell) or modulo n (periodic)."""
    return k if cell is None else k % n


@overload(wrap_index, inline="always")
def _wrap_index(k, n, cell):
    if _none(cell):
        return lambda k, n, cell: k
    return lambda k, n, cell: k % n


# ---- wrapping and deformation -------------------------------------------------------
@njit
def _wrap(cell, x):
    for i in range(x.shape[0]):
        for d in range(3):
            ln = cell[C_L + d]
            x[i, d] -= ln * math.floor(x[i, d] / ln)


def wrap(cell, x):
    """Positions x (n, 3) [m] into [0, L) (no cell: nothing)."""
    if cell is not None:
        _wrap(cell, x)


@overload(wrap)
def _wrap_switch(cell, x):
    if _none(cell):
        return lambda cell, x: None
    return lambda cell, x: _wrap(cell, x)


@njit
def _deform(cell, x, xref, dt, lim2, rebuild):
    s0 = 1.0 + cell[C_RATE] * dt
    s1 = 1.0 + cell[C_RATE + 1] * dt
    s2 = 1.0 + cell[C_RATE + 2] * dt
    cell[C_L] *= s0
    cell[C_L + 1] *= s1
    cell[C_L + 2] *= s2
    for i in range(x.shape[0]):
        x[i, 0] *= s0
        x[i, 1] *= s1
        x[i, 2] *= s2
        dx = x[i, 0] - xref[i, 0]
        dy = x[i, 1] - xref[i, 1]
        dz = x[i, 2] - xref[i, 2]
        if dx * dx + dy * dy + dz * dz > lim2:
            rebuild[0] = 1


def deform(cell, x, xref, dt, lim2, rebuild):
    """One step's affine deformation of the cell and the positions x (n, 3) [m] at the strain
    rates C_RATE [1/s] over dt [s]; flags a list rebuild when a sphere is more than skin/2 from
    its position at the last build (``lim2`` = (skin/2)^2 [m^2]). No cell: nothing."""
    if cell is not None:
        _deform(cell, x, xref, dt, lim2, rebuild)


@overload(deform)
def _deform_switch(cell, x, xref, dt, lim2, rebuild):
    if _none(cell):
        return lambda cell, x, xref, dt, lim2, rebuild: None
    return lambda cell, x, xref, dt, lim2, rebuild: _deform(cell, x, xref, dt, lim2, rebuild)


# ---- stress and servo ---------------------------------------------------------------
@njit(inline="always")
def normal_stiffness(law, prm, ma, mb, rstar, delta):
    """Tangent normal stiffness dF_n/d delta [N/m]: k_n (linear), 2 E* sqrt(R* delta) (Hertz)."""
    if law == HERTZ:
        return 2.0 * prm[ma, mb, P_ESTAR] * math.sqrt(rstar * delta)
    return prm[ma, mb, P_KN]


@njit
def cell_stress(cell, pi, pj, act, fc, xs, vs, mass, rad, smat, prm, law, out, stiff):
    """Love-Weber stress of the cell into out (6,) [Pa] (xx yy zz xy xz yz, compression
    positive, the symmetric part) and the affine stiffness K_d into stiff (3,) [Pa]; serial,
    in pair order (bit-identical for any thread count)."""
    s = np.zeros((3, 3))
    k = np.zeros(3)
    for c in range(pi.shape[0]):
        if not act[c]:
            continue
        i = pi[c]
        j = pj[c]
        b0, b1, b2 = _image(cell, xs[i, 0] - xs[j, 0], xs[i, 1] - xs[j, 1], xs[i, 2] - xs[j, 2])
        b = (b0, b1, b2)
        for a in range(3):
            for e in range(3):
                s[a, e] += fc[c, a] * b[e]
        d = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        delta = rad[i] + rad[j] - d
        if delta > 0.0 and d > 0.0:
            kn = normal_stiffness(law, prm, smat[i], smat[j], rad[i] * rad[j] / (rad[i] + rad[j]), delta)
            for a in range(3):
                k[a] += kn * b[a] ** 4 / (d * d)
    for i in range(xs.shape[0]):
        for a in range(3):
            for e in range(3):
                s[a, e] += mass[i] * vs[i, a] * vs[i, e]
    vol = cell[C_L] * cell[C_L + 1] * cell[C_L + 2]
    for m in range(6):
        a, e = _PAIRS[m]
        out[m] = 0.5 * (s[a, e] + s[e, a]) / vol
    for a in range(3):
        stiff[a] = k[a] / vol


@njit
def servo(cell, dt):
    """New strain rates: prescribed axes keep C_TARGET; stress-controlled axes
    edot = clip(beta (sigma_dd - target) / (K_d dt), +-edot_max) [1/s] (edot_max with the sign of
    the error when K_d = 0)."""
    emax = cell[C_MAX_RATE]
    for d in range(3):
        if cell[C_MODE + d] == RATE:
            cell[C_RATE + d] = cell[C_TARGET + d]
            continue
        err = cell[C_STRESS + d] - cell[C_TARGET + d]
        kd = cell[C_STIFF + d]
        if kd > 0.0 and dt > 0.0:
            rate = cell[C_GAIN] * err / (kd * dt)
        else:
            rate = emax if err > 0.0 else -emax
        cell[C_RATE + d] = min(max(rate, -emax), emax)


@njit
def _control(cell, g, nl, bd, prm, law, dt):
    cell_stress(cell, nl.pi, nl.pj, nl.act, nl.fc, g.xs, g.vs, bd.mass, g.rad, g.mat, prm, law,
                cell[C_STRESS:C_STRESS + 6], cell[C_STIFF:C_STIFF + 3])
    if dt > 0.0:
        servo(cell, dt)


def control(cell, g, nl, bd, prm, law, dt):
    """After the pair pass: the cell's stress and stiffness, then the servo's strain rates for the
    next step (not on the priming evaluation, dt = 0). No cell: nothing."""
    if cell is not None:
        _control(cell, g, nl, bd, prm, law, dt)


@overload(control)
def _control_switch(cell, g, nl, bd, prm, law, dt):
    if _none(cell):
        return lambda cell, g, nl, bd, prm, law, dt: None
    return lambda cell, g, nl, bd, prm, law, dt: _control(cell, g, nl, bd, prm, law, dt)


def cell_of(g):
    """The geometry tuple's periodic cell: ``g.cell`` where the shape has one, else None."""
    return getattr(g, "cell", None)


@overload(cell_of, inline="always")
def _cell_of(g):
    if "cell" in getattr(g, "fields", ()):
        return lambda g: g.cell
    return lambda g: None
