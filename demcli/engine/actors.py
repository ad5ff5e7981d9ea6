"""Actors: large rigid bodies that load a polyhedral bed (the loading plate, the sleeper).

An actor is an ordinary polyhedral body of the scene (exact polyhedron-polyhedron
contact with every particle) with three differences:

- it is one of the last bodies, outside the cell grid, paired by bounding sphere
  with every particle (:func:`demcli.kernels.neighbors.add_actor_pairs`): a grid cell
  sized for a 0.6 m plate would hold the whole bed;
- it moves along z only: rotation and the x, y velocity are held (flags
  FIX_ROTATION | FIX_X | FIX_Y), as the plate and the sleeper of a ballast box test
  guided by the frame (seed 002, sec. 4);
- it carries a prescribed force F(t) = F0 + F1 sin(omega max(t - t0, 0) + phase) on
  top of its weight (flag LOADED, group ``actors``), or, with ``velocity``, moves at
  a prescribed constant velocity (flag FIX_TRANSLATION).

The functions work on state groups (dicts of arrays), so stages add and remove
actors between runs of the engine.
"""

import math

import numpy as np

from demcli.engine.poly_shape import polyhedra_groups
from demcli.engine.system import is_clumped
from demcli.geometry import convex_hull
from demcli.kernels import layout as K
from demcli.state.polyhedra import ShapeTable


def box_polyhedron(size):
    """Cuboid of edge lengths ``size`` (3,) [m] centred at the origin."""
    h = 0.5 * np.asarray(size, np.float64)
    return convex_hull(np.array([[i, j, k] for i in (-h[0], h[0]) for j in (-h[1], h[1]) for k in (-h[2], h[2])]))


def haversine(f_min, f_max, frequency, start=0.0, direction=(0.0, 0.0, -1.0)):
    """Load row of a force cycling from ``f_min`` to ``f_max`` [N] along ``direction``.

    F(t) = F_min + (F_max - F_min) (1 - cos(2 pi f (t - t0))) / 2, written as
    F0 + F1 sin(2 pi f (t - t0) - pi/2) with F0 = (F_min + F_max)/2, F1 = (F_max - F_min)/2.
    Returns a dict of the ``actors`` load columns.
    """
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    return {"load_mean": 0.5 * (f_min + f_max) * d, "load_amplitude": 0.5 * (f_max - f_min) * d,
            "frequency": float(frequency), "phase": -0.5 * math.pi, "start": float(start)}


def add_actor(groups, poly, x, density, material, name, load=None, velocity=None):
    """Groups with one more body, an actor, appended after the others.

    poly: :class:`~demcli.geometry.ConvexPolyhedron` (any frame; placed with its
    centroid at ``x`` [m], orientation as given). density [kg/m^3]; material: index.
    name: role ("plate", "sleeper"). load: dict from :func:`haversine` (or None: no
    force besides gravity). velocity: (3,) m/s prescribed instead of a force.
    """
    if load is not None and velocity is not None:
        raise ValueError("an actor has a prescribed force or a prescribed velocity, not both")
    flags = K.FIX_ROTATION | K.FIX_X | K.FIX_Y
    if velocity is not None:
        flags |= K.FIX_TRANSLATION
    if load is not None:
        flags |= K.LOADED
    one = polyhedra_groups([poly], density, x=np.asarray(x, np.float64).reshape(1, 3),
                           v=None if velocity is None else np.asarray(velocity, np.float64).reshape(1, 3),
                           material=material, flags=np.array([flags], np.int8))
    if not len(groups.get("polyhedra", {}).get("shape", ())):
        groups = _as_mixed(groups, one)
    nb = len(groups["bodies"]["mass"])
    out = {k: v for k, v in groups.items()}
    bodies = {}
    for key, val in groups["bodies"].items():
        add = one["bodies"].get(key)
        if add is None:  # force, torque, angmom of the stored scene: the actor starts unloaded
            add = np.zeros((1,) + np.asarray(val).shape[1:], np.asarray(val).dtype)
        bodies[key] = np.concatenate([np.asarray(val), np.asarray(add, np.asarray(val).dtype)])
    bodies["id"][-1] = int(np.max(groups["bodies"]["id"], initial=-1)) + 1
    if "angmom" in bodies:
        bodies["angmom"][-1] = 0.0
    out["bodies"] = bodies
    ph = {}
    for key, val in groups["polyhedra"].items():
        add = np.asarray(one["polyhedra"][key])
        if key == "shape":
            add = add + len(groups["polyhedron_shapes"]["volume"])
        ph[key] = np.concatenate([np.asarray(val), add.astype(np.asarray(val).dtype)])
    out["polyhedra"] = ph
    out["polyhedron_shapes"] = ShapeTable.concat([ShapeTable.from_group(groups["polyhedron_shapes"]),
                                                 ShapeTable.from_group(one["polyhedron_shapes"])]).to_group()
    row = load if load is not None else haversine(0.0, 0.0, 0.0)
    old = groups.get("actors", {})
    actors = {"body": np.array([nb], np.int64), "name": np.array([name], dtype=object),
              "load_mean": np.asarray(row["load_mean"], np.float64).reshape(1, 3),
              "load_amplitude": np.asarray(row["load_amplitude"], np.float64).reshape(1, 3),
              "frequency": np.array([row["frequency"]]), "phase": np.array([row["phase"]]),
              "start": np.array([row["start"]])}
    if len(old):
        actors = {k: np.concatenate([np.asarray(old[k]), v]) for k, v in actors.items()}
    out["actors"] = actors
    return out


def _as_mixed(groups, one):
    """A sphere or clump scene's groups readied for its first polyhedral body (a mixed scene,
    :mod:`demcli.engine.mixed_shape`): every body a rigid rotor with three principal moments
    (a single sphere's (n, 1) inertia broadcast), and empty ``polyhedra`` / ``polyhedron_shapes``
    groups with the columns of ``one`` (groups of one polyhedron)."""
    out = dict(groups)
    bodies = dict(groups["bodies"])
    inert = np.asarray(bodies["inertia"], np.float64)
    bodies["inertia"] = np.ascontiguousarray(np.broadcast_to(inert.reshape(len(inert), -1), (len(inert), 3)))
    out["bodies"] = bodies
    out["polyhedra"] = {k: np.asarray(v)[:0] for k, v in one["polyhedra"].items()}
    out["polyhedron_shapes"] = ShapeTable.from_group(one["polyhedron_shapes"]).subset(np.zeros(0, np.int64)).to_group()
    return out


def actor_index(groups, name):
    """Body index of the actor ``name`` (None when the scene has none)."""
    a = groups.get("actors", {})
    for b, n in zip(np.asarray(a.get("body", [])), np.asarray(a.get("name", []))):
        if (n.decode() if isinstance(n, bytes) else str(n)) == name:
            return int(b)
    return None


def remove_actors(groups):
    """Groups without the actors (the particles keep their indices; their contacts with
    actors are dropped)."""
    a = groups.get("actors", {})
    if not len(a) or not len(a["body"]):
        return {k: v for k, v in groups.items() if k != "actors"}
    n = int(np.min(a["body"]))
    out = {k: v for k, v in groups.items() if k != "actors"}
    out["bodies"] = {k: np.asarray(v)[:n].copy() for k, v in groups["bodies"].items()}
    first = len(groups["bodies"]["mass"]) - len(groups["polyhedra"]["shape"])  # body of polyhedra row 0
    ph = {k: np.asarray(v)[:n - first].copy() for k, v in groups["polyhedra"].items()}
    if first and not len(ph["shape"]):  # a sphere or clump bed again: as before its first actor
        del out["polyhedra"], out["polyhedron_shapes"]
        out.pop("sphere_body_contacts", None)
        if not is_clumped(out):
            out["bodies"]["inertia"] = out["bodies"]["inertia"][:, :1].copy()
        return out
    keep = np.unique(ph["shape"])
    out["polyhedron_shapes"] = ShapeTable.from_group(groups["polyhedron_shapes"]).subset(keep).to_group()
    ph["shape"] = np.searchsorted(keep, ph["shape"]).astype(np.int64)
    out["polyhedra"] = ph
    if "sphere_body_contacts" in groups:
        c = groups["sphere_body_contacts"]
        m = np.asarray(c["body"]) < n
        out["sphere_body_contacts"] = {k: np.asarray(v)[m].copy() for k, v in c.items()}
    if "body_contacts" in groups:
        c = groups["body_contacts"]
        m = (np.asarray(c["i"]) < n) & (np.asarray(c["j"]) < n)
        out["body_contacts"] = {k: np.asarray(v)[m].copy() for k, v in c.items()}
    if "body_wall_contacts" in groups:
        c = groups["body_wall_contacts"]
        m = np.asarray(c["body"]) < n
        out["body_wall_contacts"] = {k: np.asarray(v)[m].copy() for k, v in c.items()}
    return out
