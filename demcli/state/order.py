"""Particles stored in spatial (cell) order, so that neighbours sit near each other in memory.

The contact kernels read the positions and velocities of both spheres of every listed pair;
when the pair's spheres are far apart in the arrays, each contact costs a cache miss. On the
dense 10 000-sphere scene (``python bench/bench_spheres.py 10000 dense 20000 T --order
lattice|shuffle|cells``, 2026-11-22, one quiet window) shuffled spheres run at 1.88e7
particle-steps/s against 2.61e7 in lattice order on one thread, 2.51e7 against 4.33e7 on two;
shuffled and then put in cell order, 2.57e7 and 4.09e7. So the stages that place spheres
store them in cell order (generate and carve: :func:`spatial_permutation`; prepare, which
creates and bonds its specimen in one stage: cells of one diameter), and a
dynamic stage (``orders_particles`` in :class:`demcli.stages.base.StageType`) re-stores a fresh
sphere scene in that order before it starts: a scene built otherwise (clumps made from an
assembled polyhedral bed, a state written by other software) may be in random order.

The permutation is generic over the state schema (:mod:`demcli.state.fields`): every
registered field whose rows are bodies (``n_b``) or spheres (``n_s``) is permuted, every
integer field that indexes them (``index_of``) is renumbered, and the rows of a group that
point at bodies (``aggregates/body``) follow them. Body ids (``bodies/id``) travel with their
bodies, so a body keeps its identity in records and snapshots. The order is a deterministic
function of the input state (positions, and input order within a cell), whatever the thread
count.

A scene is left as it is when it holds oriented pairs (contacts, bonds, polyhedron contacts
store i < j with history whose sign depends on that orientation), actors (they are the last
bodies: :func:`demcli.engine.actors.remove_actors`), a checkpoint, or a field outside the
schema. So a scene that gains particles after its first dynamic stage keeps its order while
it holds contacts (mastic balls appended to a compacted skeleton); a cut that leaves no
contacts lets the next dynamic stage reorder it (the tests follow bodies by id). Scenes of
polyhedra (no spheres) are left as they are too: their step is bound by the narrow phase's
arithmetic, and a settled 4238-polyhedron bed ran as fast in assembly order as in cell order
(1.13-1.17e5 against 1.08-1.14e5 body-steps/s, one thread, three alternated runs).

Only the start of a stage reorders: bodies keep their rows while the stage runs, since its
hooks and records refer to them by row (a plate, a loaded sleeper). The pipeline hashes the
input after reordering it, so a checkpoint or an output made from another order is not taken
for this one.
"""

from __future__ import annotations

import numpy as np

from demcli.state import fields

PAIR_GROUPS = ("contacts", "bonds", "body_contacts")
"""Groups of i < j pairs with oriented history: a scene holding any is not reordered."""
KEEP_GROUPS = PAIR_GROUPS + ("actors", "checkpoint")
"""Groups whose presence leaves a scene as it is (actors are the last bodies; a checkpoint's
rows follow its run's order)."""


def cell_order(points, cell):
    """Indices sorting points (n, d) by the cell of side ``cell`` [m] they fall in, x fastest
    and z slowest, stable (points in one cell keep their order).

    Row order of cells rather than a Morton curve: on the dense sphere scene both run alike
    at 10 000 spheres, and at 10^6 the rows are 5 % faster (the neighbour lists then read
    memory in long forward runs, which the hardware prefetcher follows).
    """
    points = np.asarray(points, np.float64)
    if len(points) == 0:
        return np.zeros(0, np.int64)
    c = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
    return np.lexsort(tuple(c[:, a] for a in range(c.shape[1])))


def spatial_permutation(points):
    """The order in which placed particles are stored: :func:`cell_order` with cells of the
    mean spacing (about one particle per cell)."""
    if len(points) == 0:
        return np.zeros(0, np.int64)
    return cell_order(points, mean_spacing(points))


def mean_spacing(points):
    """(bounding-box volume / n)^(1/d) over the axes the points span [m] (1 when they span none)."""
    points = np.asarray(points, np.float64)
    span = points.max(axis=0) - points.min(axis=0)
    span = span[span > 0.0]
    return float(np.prod(span) / len(points)) ** (1.0 / len(span)) if len(span) else 1.0


def unsafe_reason(state):
    """Why ``state`` cannot be reordered (a text), or None when it can."""
    for g in KEEP_GROUPS:
        arrays = state.groups.get(g, {})
        if any(len(np.atleast_1d(a)) for a in arrays.values()):
            return f"it holds {g}"
    for g, arrays in state.groups.items():
        top = fields.GROUPS.get(g.split("/", 1)[0])
        if top is not None and top.tables:
            continue
        for name in arrays:
            if f"{g}/{name}" not in fields.FIELDS:
                return f"field {g}/{name} is not in the state schema"
    return None


def spatial_order(state):
    """A copy of ``state`` with bodies in cell order and spheres grouped by body in that order.

    Returns ``(state, moved)``: ``state`` itself (not a copy) when it has no spheres, is
    already in that order, or cannot be reordered (:func:`unsafe_reason`); ``moved`` is True
    when the order changed.
    """
    fields.register_all()  # every stage's and effect's fields: the permutation is schema-driven
    x = state.get("bodies/x")
    if x is None or len(x) < 2 or len(state.get("spheres/radius", ())) == 0 or unsafe_reason(state) is not None:
        return state, False
    x = np.asarray(x)[:, :int(state.meta.get("dim", 3))]
    pb = spatial_permutation(x)
    ps = np.argsort(_inverse(pb)[np.asarray(state["spheres/body"], np.int64)], kind="stable")
    if np.array_equal(pb, np.arange(len(pb))) and np.array_equal(ps, np.arange(len(ps))):
        return state, False
    perm = {"n_b": pb, "n_s": ps}
    inv = {k: _inverse(p) for k, p in perm.items()}
    out = fields.State(meta=dict(state.meta), groups={}, group_attrs=dict(state.group_attrs))
    for g, arrays in state.groups.items():
        new = {}
        owner = None  # a row dim whose rows point at bodies or spheres (aggregates/body, wall_contacts/sphere)
        for name, a in arrays.items():
            spec = fields.FIELDS.get(f"{g}/{name}")
            if spec is not None and not spec.attr and spec.dims and spec.dims[0] in perm:
                a = np.asarray(a)[perm[spec.dims[0]]]
            if spec is not None and spec.index_of in inv and len(np.atleast_1d(a)):
                a = np.asarray(a)
                a = np.where(a >= 0, inv[spec.index_of][np.maximum(a, 0)], a).astype(a.dtype)
                if spec.dims and spec.dims[0] not in perm and owner is None:
                    owner = (spec.dims[0], a)
            new[name] = a
        if owner is not None:
            # such rows follow their bodies, so that rows listed in body order stay so
            # (the cut stage takes aggregate k to be body k)
            rows = np.argsort(owner[1], kind="stable")
            for name, a in new.items():
                spec = fields.FIELDS.get(f"{g}/{name}")
                if spec is not None and not spec.attr and spec.dims and spec.dims[0] == owner[0]:
                    new[name] = np.asarray(a)[rows]
        out.groups[g] = new
    return out, True


def body_rows_by_id(state):
    """Body rows in ascending ``bodies/id``: follows bodies across stages whatever their order."""
    return np.argsort(np.asarray(state["bodies/id"]), kind="stable")


def sphere_rows_by_id(state):
    """Sphere rows grouped by body in ascending body id, each body's members in stored order."""
    rank = _inverse(body_rows_by_id(state))
    return np.argsort(rank[np.asarray(state["spheres/body"], np.int64)], kind="stable")


def _inverse(p):
    """The inverse of a permutation: inv[p[k]] = k."""
    inv = np.empty_like(p)
    inv[p] = np.arange(len(p))
    return inv
