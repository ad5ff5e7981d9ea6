"""Spatial (cell) order of a scene: cell_order and the schema-driven spatial_order."""

import numpy as np
import pytest

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls
from demcli.state.fields import example_state, register_all, validate
from demcli.state.order import (body_rows_by_id, cell_order, mean_spacing, spatial_order, spatial_permutation,
                                 sphere_rows_by_id)

register_all()  # every stage's fields, as in a run


def test_cell_order_sorts_cells_z_slowest_and_keeps_ties_in_order():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0.0, 1.0, (500, 3))
    order = cell_order(pts, 0.25)
    c = np.floor((pts[order] - pts.min(axis=0)) / 0.25).astype(int)
    key = (c[:, 2] * 4 + c[:, 1]) * 4 + c[:, 0]
    assert np.all(np.diff(key) >= 0)
    for k in np.unique(key):  # stable: one cell's points keep their input order
        assert np.all(np.diff(order[key == k]) > 0)
    assert cell_order(np.zeros((0, 3)), 1.0).shape == (0,)


def test_mean_spacing_of_a_lattice_and_of_a_plane():
    g = np.stack(np.meshgrid(*[np.arange(10.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    assert mean_spacing(g) == pytest.approx(9.0 / 10.0, rel=1e-12)  # (9^3 / 1000)^(1/3)
    flat = g[g[:, 2] == 0.0]
    assert mean_spacing(flat) == pytest.approx(9.0 / 10.0, rel=1e-12)  # only the axes spanned


def _clumped_state(n_b=40, seed=1):
    st = example_state(n_bodies=n_b, spheres_per_body=3, seed=seed, contacts=False)
    st.groups.pop("contacts", None)
    return st


def _by_id(st):
    """Per body id: its row of every body field, and its spheres' rows in their order."""
    ids = st["bodies/id"]
    out = {}
    for r, i in enumerate(ids):
        rows = {k: np.asarray(v[r]) for k, v in st.groups["bodies"].items()}
        members = np.flatnonzero(st["spheres/body"] == r)
        rows.update({f"s_{k}": np.asarray(v)[members] for k, v in st.groups["spheres"].items() if k != "body"})
        out[int(i)] = rows
    return out


def test_spatial_order_permutes_every_body_and_sphere_field_and_renumbers_indices():
    st = _clumped_state()
    validate(st)
    out, moved = spatial_order(st)
    assert moved
    validate(out)
    # bodies in cell order of their centres
    x = out["bodies/x"]
    assert np.array_equal(cell_order(x, mean_spacing(x)), np.arange(len(x)))
    # every body carries its own data and its own spheres (members keep their order)
    before, after = _by_id(st), _by_id(out)
    assert before.keys() == after.keys()
    for i in before:
        for k in before[i]:
            np.testing.assert_array_equal(after[i][k], before[i][k], err_msg=f"body id {i}, {k}")
    # spheres grouped by body, bodies ascending
    assert np.all(np.diff(out["spheres/body"]) >= 0)
    # rows that point at spheres are renumbered, and follow their spheres
    def wall_rows(s):
        sph = s["wall_contacts/sphere"]
        return sorted((int(s["bodies/id"][s["spheres/body"][i]]), int(w), tuple(s["spheres/offset"][i]))
                      for i, w in zip(sph, s["wall_contacts/wall"]))

    assert wall_rows(out) == wall_rows(st)
    assert np.all(np.diff(out["wall_contacts/sphere"]) >= 0)
    # the input is untouched, and ordering twice changes nothing
    assert st == _clumped_state()
    again, moved2 = spatial_order(out)
    assert not moved2 and again is out


@pytest.mark.parametrize("group", ["contacts", "bonds", "body_contacts"])
def test_a_scene_with_oriented_pairs_is_left_as_it_is(group):
    st = _clumped_state()
    st[f"{group}/i"] = np.array([0], np.int64)
    st[f"{group}/j"] = np.array([5], np.int64)
    out, moved = spatial_order(st)
    assert out is st and not moved


def test_a_scene_with_actors_is_left_as_it_is():
    """Actors are the last bodies (remove_actors cuts the scene there)."""
    st = _clumped_state()
    st["actors/body"] = np.array([len(st["bodies/x"]) - 1], np.int64)
    st["actors/name"] = np.array(["plate"], dtype=object)
    out, moved = spatial_order(st)
    assert out is st and not moved


def test_a_field_outside_the_schema_leaves_the_scene_as_it_is():
    st = _clumped_state()
    st["bodies/mystery"] = np.zeros(len(st["bodies/x"]))
    out, moved = spatial_order(st)
    assert out is st and not moved


def _bed_groups(n, seed):
    """A lattice bed of n spheres (radius 1 mm, slightly overlapping), in random order."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(n ** (1 / 3)))
    idx = rng.permutation(side ** 3)[:n]
    pos = np.stack([idx % side, (idx // side) % side, idx // side ** 2], 1) * 1.995e-3 + 1e-3
    pos += rng.uniform(-4e-5, 4e-5, pos.shape)
    m = np.full(n, 2650.0 * 4.0 / 3.0 * np.pi * 1e-9)
    return {"bodies": {"x": pos, "v": rng.uniform(-0.05, 0.05, (n, 3)), "omega": np.zeros((n, 3)),
                       "q": np.tile([1.0, 0, 0, 0], (n, 1)), "mass": m, "inertia": np.repeat(0.4 * m[:, None] * 1e-6, 3, 1),
                       "flags": np.zeros(n, np.int8), "id": np.arange(n, dtype=np.int64)},
            "spheres": {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)), "radius": np.full(n, 1e-3),
                        "material": np.zeros(n, np.int64)}}


def _run(groups, steps):
    box = float(groups["bodies"]["x"].max()) + 1e-3
    sys_ = System(groups, [Material("glass", 2650.0, friction=0.5)], ContactModel(law="linear", kn=1e4, kt=2.5e3),
                  make_plan(["gravity", "friction"], walls=True), Walls.box_faces((box, box, box)),
                  Dynamics(gravity=(0, 0, -9.81), skin=0.3), dt=2e-6)
    sys_.advance(steps)
    return sys_


def test_a_reordered_scene_moves_as_the_original_one():
    """The same jammed bed stored in its random order and in cell order: after 1000 steps
    (contacts opening, closing and sliding; speeds 0.02 m/s, spins 40 rad/s) every body, found
    by id, moves as in the other run to round-off: the force sums run in another order, so not
    bit for bit, and the bed amplifies round-off tenfold per ~300 steps (1e-13 m/s at 300 steps,
    7e-12 at 1000, 1e-8 at 3000). A body given another's data would differ by its whole speed."""
    from demcli.state.fields import State

    groups = _bed_groups(343, seed=5)
    st = State(meta={"dim": 3}, groups={k: dict(v) for k, v in groups.items()})
    ordered, moved = spatial_order(st)
    assert moved
    a = _run(groups, 1000)
    b = _run(ordered.groups, 1000)
    assert a.contact_count()[0] > 150  # the bed is jammed: the test exercises contacts
    assert b.contact_count() == a.contact_count()
    ia = np.argsort(a.body_id)
    ib = np.argsort(b.body_id)
    np.testing.assert_allclose(b.x[ib], a.x[ia], rtol=0, atol=1e-14)
    np.testing.assert_allclose(b.v[ib], a.v[ia], rtol=0, atol=1e-10)
    np.testing.assert_allclose(b.w[ib], a.w[ia], rtol=0, atol=1e-7)


def test_a_dem_stage_stores_a_shuffled_input_in_cell_order_and_keeps_ids(tmp_path):
    """generate -> dem on the bead smoke case, the generate state shuffled in between: the dem
    stage logs the reordering, its output is in cell order with every body's id, radius and
    material kept, and the beads settle as in the unshuffled run (same count, a close mean
    height: another summation order, so another realisation of the same settling)."""
    from pathlib import Path

    from demcli import run_case
    from demcli.state import read_state, write_state

    case = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "beads.yaml"
    run_case(case, out=tmp_path / "ref", quiet=True, overrides=["stages.settle.time.steps=600"])
    run_case(case, out=tmp_path / "mix", quiet=True, only="pour")
    st = read_state(tmp_path / "mix" / "00-pour.h5")
    x = st["bodies/x"]
    assert np.array_equal(spatial_order(st)[0]["bodies/x"], x)  # generate stores cell order
    perm = np.random.default_rng(0).permutation(len(x))
    inv = np.argsort(perm)
    for name in list(st.groups["bodies"]):
        st[f"bodies/{name}"] = np.asarray(st[f"bodies/{name}"])[perm]
    st["spheres/body"] = inv[np.asarray(st["spheres/body"])]
    write_state(tmp_path / "mix" / "00-pour.h5", st)
    run_case(case, out=tmp_path / "mix", quiet=True, from_stage="settle", overrides=["stages.settle.time.steps=600"])
    assert "particles stored in cell order" in (tmp_path / "mix" / "log.txt").read_text()
    out = read_state(tmp_path / "mix" / "01-settle.h5")
    ref = read_state(tmp_path / "ref" / "01-settle.h5")
    np.testing.assert_array_equal(out["bodies/id"], st["bodies/id"][spatial_permutation(st["bodies/x"])])
    x0 = read_state(tmp_path / "ref" / "00-pour.h5")["bodies/x"]
    assert np.array_equal(spatial_permutation(x0), np.arange(len(x0)))
    ro, rr = sphere_rows_by_id(out), sphere_rows_by_id(ref)
    for name in ("radius", "material"):
        np.testing.assert_array_equal(out[f"spheres/{name}"][ro], ref[f"spheres/{name}"][rr])
    np.testing.assert_array_equal(out["bodies/mass"][body_rows_by_id(out)], ref["bodies/mass"][body_rows_by_id(ref)])
    assert abs(out["bodies/x"][:, 2].mean() - ref["bodies/x"][:, 2].mean()) < 0.05 * ref["bodies/x"][:, 2].mean()
