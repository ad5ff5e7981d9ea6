"""Unit-quaternion helpers for rigid-body orientation (scalar first: w, x, y, z).

A quaternion q maps body-frame vectors to the world frame: v_world = q v_body q*.
All helpers are scalar-level: plain calls, which LLVM inlines (numba's own inlining would
enlarge every caller's IR, which its passes then process at each call site).
"""

import math

from demcli.jit import njit


@njit(internal=True)
def rotate(qw, qx, qy, qz, vx, vy, vz):
    """World vector of body vector v under q (v' = q v q*), via t = 2 q_v x v."""
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + (qy * tz - qz * ty),
            vy + qw * ty + (qz * tx - qx * tz),
            vz + qw * tz + (qx * ty - qy * tx))


@njit(internal=True)
def rotate_inv(qw, qx, qy, qz, vx, vy, vz):
    """Body vector of world vector v under q (v' = q* v q)."""
    return rotate(qw, -qx, -qy, -qz, vx, vy, vz)


@njit(internal=True)
def mul(aw, ax, ay, az, bw, bx, by, bz):
    """Hamilton product a b."""
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


@njit(internal=True)
def exp_rotation(wx, wy, wz, h):
    """Unit quaternion of the rotation by angle |w| h about w (exponential map)."""
    ang = math.sqrt(wx * wx + wy * wy + wz * wz) * h
    if ang < 1e-12:
        # second-order series keeps the map smooth at zero angle
        return 1.0 - ang * ang / 8.0, 0.5 * h * wx, 0.5 * h * wy, 0.5 * h * wz
    s = math.sin(0.5 * ang) / (ang / h)
    return math.cos(0.5 * ang), s * wx, s * wy, s * wz


@njit(internal=True)
def normalize(qw, qx, qy, qz):
    """q / |q|."""
    inv = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return qw * inv, qx * inv, qy * inv, qz * inv
