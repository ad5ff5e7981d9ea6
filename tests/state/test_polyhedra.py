"""Polyhedron shape tables (CSR): building, subsets, concatenation, and registry validation."""

import numpy as np
import pytest

from demcli.errors import StateError
from demcli.geometry import random_polyhedron
from demcli.state import new_state, validate
from demcli.state.polyhedra import SHAPE_FIELDS, ShapeTable, rotation_matrices, world_vertices


def polys(n=4, seed=0):
    rng = np.random.default_rng(seed)
    return [random_polyhedron(rng, int(rng.integers(6, 12)), rng.uniform(0.5, 1.5, 3)) for _ in range(n)]


def same(a, b):
    return all(np.array_equal(getattr(a, f), getattr(b, f)) for f in SHAPE_FIELDS)


def test_templates_are_in_the_principal_frame():
    p = polys(1)[0]
    t = ShapeTable.from_polyhedra([p], scales=[2.0])
    v, faces, normals, offsets, edges = t.shape(0)
    assert np.allclose(v, 2.0 * (p.vertices - p.centroid) @ p.principal_axes)
    assert [f.tolist() for f in faces] == [f.tolist() for f in p.faces]
    assert np.allclose(v @ normals.T <= offsets[None, :] + 1e-12, True)
    assert t.volume[0] == pytest.approx(8 * p.volume) and np.allclose(t.inertia[0], 32 * p.principal_moments)
    assert np.array_equal(edges, p.edges)


def test_subset_and_concat_are_consistent_with_building_directly():
    ps = polys()
    t = ShapeTable.from_polyhedra(ps)
    assert same(t.subset([2, 0, 2]), ShapeTable.from_polyhedra([ps[2], ps[0], ps[2]]))
    assert same(ShapeTable.concat([t.subset([0]), t.subset([1, 2, 3])]), t)


def test_state_groups_validate_and_bad_indices_are_caught():
    ps = polys(3)
    t = ShapeTable.from_polyhedra(ps)
    st = new_state("s", "assemble")
    n = 3
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    st.groups["bodies"] = {"x": np.eye(3) * 5, "v": np.zeros((n, 3)), "q": q, "omega": np.zeros((n, 3)),
                           "mass": t.volume, "inertia": t.inertia, "id": np.arange(n), "flags": np.zeros(n, np.int8)}
    st.groups["spheres"] = {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)), "radius": np.zeros(0),
                            "material": np.zeros(0, np.int64)}
    st.groups["materials"] = {"name": np.array(["rock"], dtype=object),
                              **{k: np.ones(1) for k in ("density", "young", "poisson", "friction",
                                                         "rolling_friction", "restitution")}}
    st.groups["polyhedra"] = {"shape": np.arange(n), "material": np.zeros(n, np.int64),
                              "size_class": np.zeros(n, np.int64), "sieve_size": np.ones(n),
                              "library_index": np.arange(n), "flaky": np.zeros(n, bool),
                              "elongated": np.zeros(n, bool)}
    st.groups["polyhedron_shapes"] = t.to_group()
    validate(st)
    v, owner = world_vertices(st)
    assert np.allclose(v[owner == 1], t.shape(1)[0] + [0, 5, 0])
    st.groups["polyhedra"]["shape"] = np.array([0, 1, 3])
    with pytest.raises(StateError, match="polyhedra/shape"):
        validate(st)


def test_rotation_matrices_are_rotations():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(5, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    r = rotation_matrices(q)
    assert np.allclose(r @ r.transpose(0, 2, 1), np.eye(3)) and np.allclose(np.linalg.det(r), 1.0)
    # (w, x, y, z) = (cos 45, 0, 0, sin 45): a quarter turn about z takes x to y
    assert np.allclose(rotation_matrices([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])[0] @ [1, 0, 0], [0, 1, 0])
