"""Fixtures of the kernel tests: flat triangle meshes."""

import numpy as np
import pytest

from demcli.geometry.mesh_file import rotation_matrix


def grid_mesh(n, size, rot=(0.0, 0.0, 0.0), shift=(0.0, 0.0, 0.0), seed=None):
    """Flat n x n squares of edge ``size`` in z = 0, each split in two triangles (diagonals in
    alternating directions; vertices jittered in-plane when ``seed``), rotated then shifted."""
    xs = np.arange(n + 1) * size
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    verts = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    if seed is not None:
        inner = (gx.ravel() > 0) & (gx.ravel() < xs[-1]) & (gy.ravel() > 0) & (gy.ravel() < xs[-1])
        verts[inner, :2] += np.random.default_rng(seed).uniform(-0.2, 0.2, (inner.sum(), 2)) * size
    tris = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            tris += [(a, b, c), (a, c, d)] if (i + j) % 2 else [(a, b, d), (b, c, d)]
    rot_m = rotation_matrix(rot)
    return np.ascontiguousarray(verts @ rot_m.T + shift), np.array(tris, np.int64), rot_m @ [0.0, 0.0, 1.0]


@pytest.fixture(name="grid_mesh")
def grid_mesh_fixture():
    """:func:`grid_mesh`, for the tests that build flat meshes."""
    return grid_mesh
