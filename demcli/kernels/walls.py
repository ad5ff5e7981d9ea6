"""Rigid wall geometry: signed distance from a sphere centre to a wall surface.

Kinds: ``PLANE`` (infinite plane through ``point`` with unit ``normal`` pointing into
the domain), ``CYLINDER`` (inside of a cylinder of ``radius`` around the axis through
``point`` with unit direction ``normal``) and ``MESH`` (a triangle mesh, vertices relative to
``point``, both sides; ``normal`` only sets the direction of servo and force motion; contacts
in :mod:`demcli.kernels.mesh`). Walls translate with velocity ``v``; they do not rotate. A
wall's normal motion is controlled by ``control[w]`` and the parameter row ``wprm[w, :]``
(columns ``W_*`` below).
"""

import math

from demcli.jit import njit
from demcli.kernels.mesh import nearest_feature

PLANE = 0
CYLINDER = 1
MESH = 2

# wall control modes
FIXED = 0
VELOCITY = 1
FORCE = 2
SERVO = 3
PRESSURE = 4       # cylinders: a membrane of mass W_MASS whose radius moves under the pressure W_TARGET

# columns of wprm[w, :]
W_TARGET = 0      # FORCE: mean applied force [N] along +normal (into the domain); SERVO: target stress [Pa];
                  # PRESSURE: [Pa]
W_AMPLITUDE = 1   # FORCE: sinusoidal amplitude [N]
W_FREQ = 2        # FORCE: frequency [Hz]
W_MASS = 3        # FORCE, PRESSURE: wall mass [kg]
W_GAIN = 4        # SERVO: relaxation alpha in (0, 1]: gain G = alpha A / (sum (k_n + c_n/dt) dt), PFC-style
W_VMAX = 5        # SERVO: speed limit [m/s]
W_AREA = 6        # SERVO, PRESSURE: loaded area [m^2]
W_RATE = 7        # PRESSURE: rate of change of the radius [m/s]
W_PHASE = 8       # FORCE: phase of the sine at W_START [rad]
W_START = 9       # FORCE: time the oscillation starts [s]; before it the force holds its value there
N_WPARAMS = 10


@njit(inline="always")
def applied_force(target, amplitude, frequency, phase, start, time):
    """FORCE walls: F(t) = target + amplitude sin(2 pi frequency max(t - start, 0) + phase) [N],
    along the wall normal (into the domain); the load form of the polyhedral actors
    (:mod:`demcli.engine.actors`), so that phase -pi/2 gives a haversine cycle from
    target - amplitude held until ``start``."""
    return target + amplitude * math.sin(2.0 * math.pi * frequency * max(time - start, 0.0) + phase)


@njit(inline="always")
def wall_distance(kind, px, py, pz, ax, ay, az, radius, x, y, z):
    """Distance s from a point to the wall surface and the unit normal from wall to point.

    Returns (s, nx, ny, nz); a sphere of radius r touches the wall when s < r.
    """
    dx = x - px
    dy = y - py
    dz = z - pz
    if kind == PLANE:
        return dx * ax + dy * ay + dz * az, ax, ay, az
    # cylinder, inside: radial vector from the axis
    t = dx * ax + dy * ay + dz * az
    rx = dx - t * ax
    ry = dy - t * ay
    rz = dz - t * az
    rho = math.sqrt(rx * rx + ry * ry + rz * rz)
    if rho < 1e-300:
        return radius, 1.0, 0.0, 0.0
    inv = 1.0 / rho
    return radius - rho, -rx * inv, -ry * inv, -rz * inv


@njit
def surface_distance(kind, px, py, pz, ax, ay, az, radius, x, y, z, mesh, w, reach):
    """:func:`wall_distance` for every kind: a mesh wall (w, its arrays ``mesh``) gives its nearest
    contact within ``reach`` [m] (:func:`demcli.kernels.mesh.nearest_feature`; s = reach when none).
    ``mesh`` None (no mesh wall): the mesh path is not compiled (:mod:`demcli.kernels.switch`)."""
    if mesh is None:
        return wall_distance(kind, px, py, pz, ax, ay, az, radius, x, y, z)
    if kind == MESH:
        return nearest_feature(mesh, w, px, py, pz, x, y, z, reach)
    return wall_distance(kind, px, py, pz, ax, ay, az, radius, x, y, z)
