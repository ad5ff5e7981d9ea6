"""The mixed shape plug-in of :class:`demcli.engine.system.System`: spheres and polyhedra together.

A state with a non-empty ``spheres`` group and a non-empty ``polyhedra`` group: the sphere
bodies (single spheres or clumps; ``spheres.body`` < the first polyhedron body) come first,
the polyhedra last, one row of ``polyhedra`` per polyhedral body in body order (e.g. a
polyhedral loading plate or sleeper on a bed of spheres or clumps of spheres). Every body is
a rigid rotor (``bodies.inertia`` (n_b, 3): principal moments; a sphere's three equal). The
kernels and the contact physics are in :mod:`demcli.kernels.shapes.mixed`: sphere pairs by the
sphere law of the contact model, polyhedron pairs by the volumetric law, sphere-polyhedron
pairs by the sphere law at the point contact of the sphere with the polyhedron's nearest
feature. Walls: planes. Contacts are stored by kind: ``contacts`` and ``wall_contacts``
(spheres, as in a spheres-only scene), ``body_contacts`` and ``body_wall_contacts`` (polyhedral
bodies, as in a polyhedra-only scene) and ``sphere_body_contacts`` (sphere, polyhedral body).
"""

import math
from types import SimpleNamespace

import numpy as np

from demcli.engine.bonds import BondSet
from demcli.engine.materials import LAWS, critical_time_step, pair_table
from demcli.engine.poly_shape import BOUND_PAD, PolyShape, poly_pair_table, shape_tables, world_rows
from demcli.engine.sphere_shape import SphereShape, _empty2, contacts_tuple, stored_contacts
from demcli.kernels import layout as K
from demcli.kernels.bonds import N_BTABLE
from demcli.kernels.contact import P_MU
from demcli.kernels.walls import PLANE


def is_mixed(groups):
    """Whether the state holds both spheres and polyhedra."""
    return (len(groups.get("polyhedra", {}).get("shape", ())) > 0
            and len(groups.get("spheres", {}).get("radius", ())) > 0)


def mixed_groups(sphere_groups, poly_groups):
    """State groups of a scene with the bodies of ``sphere_groups`` (bodies, spheres: single
    spheres or clumps) followed by those of ``poly_groups`` (bodies, polyhedra,
    polyhedron_shapes, e.g. from :func:`demcli.engine.poly_shape.polyhedra_groups`). Body ids are
    renumbered in that order; a sphere body's inertia (n, 1) becomes its three principal moments."""
    bs, bp = sphere_groups["bodies"], poly_groups["bodies"]
    ns_b = len(bs["mass"])
    bodies = {}
    for key in ("x", "v", "omega", "q", "mass", "flags"):
        bodies[key] = np.concatenate([np.asarray(bs[key]), np.asarray(bp[key])]).astype(np.asarray(bp[key]).dtype)
    inert = np.asarray(bs["inertia"], np.float64).reshape(ns_b, -1)
    bodies["inertia"] = np.concatenate([np.broadcast_to(inert, (ns_b, 3)), np.asarray(bp["inertia"], np.float64)])
    bodies["id"] = np.arange(len(bodies["mass"]), dtype=np.int64)
    out = {k: {c: np.asarray(a).copy() for c, a in g.items()} for k, g in poly_groups.items()
           if k in ("polyhedra", "polyhedron_shapes")}
    out["bodies"] = bodies
    out["spheres"] = {c: np.asarray(a).copy() for c, a in sphere_groups["spheres"].items()}
    return out


class MixedShape:
    """Spheres (single or clumped) and convex polyhedra: the system's primitive arrays (spheres
    first, then one per polyhedron) and the engine's tuples."""

    name = "mixed"
    MUTABLE = ("xs", "vs", "ws", "fs", "ts")
    FRICTION = P_MU  # column of prm with the friction between spheres (the bed's pairs; qprm has the actors')

    def __init__(self, s, groups):
        if len(s.walls) and np.any(np.asarray(s.walls.kind) != PLANE):
            raise ValueError("a scene of spheres and polyhedra supports plane walls only")
        if s.plan.has("bonds"):
            raise ValueError("bonds join spheres of a spheres-only scene, not of a scene with polyhedra")
        s.law = LAWS[s.model.law]
        s.prm = pair_table(s.materials, s.model)
        s.qprm = poly_pair_table(s.materials, s.model)
        sp, ph, sh = groups["spheres"], groups["polyhedra"], groups["polyhedron_shapes"]
        s._poly_group = {k: np.asarray(val) for k, val in ph.items()}
        s._shape_group = {k: np.asarray(val) for k, val in sh.items()}
        nb = len(s.mass)
        npoly = len(ph["shape"])
        s.nbs = nb - npoly  # sphere bodies
        sbody = np.asarray(sp["body"], np.int64)
        if npoly > nb or (len(sbody) and (sbody.min() < 0 or sbody.max() >= s.nbs)):
            raise ValueError("spheres must belong to the bodies before the polyhedra (the last len(polyhedra))")
        if np.asarray(s.inert).shape != (nb, 3):
            raise ValueError("a scene of spheres and polyhedra needs principal moments of inertia (n_b, 3)")
        s.ns = len(sbody)
        s.bmat = np.ascontiguousarray(ph["material"], np.int64)
        s.pshape = np.ascontiguousarray(ph["shape"], np.int64)
        s.sbody = np.ascontiguousarray(np.concatenate([sbody, np.arange(s.nbs, nb)]), np.int64)
        s.soff = np.ascontiguousarray(np.concatenate([np.asarray(sp["offset"], np.float64).reshape(-1, 3),
                                                      np.zeros((npoly, 3))]))
        prad = np.asarray(sh["radius"], np.float64)[s.pshape] * (1.0 + BOUND_PAD)
        s.rad = np.ascontiguousarray(np.concatenate([np.asarray(sp["radius"], np.float64), prad]))
        s.smat = np.ascontiguousarray(np.concatenate([np.asarray(sp["material"], np.int64), s.bmat]))
        s.clumps = True  # every body has member primitives (a polyhedron: one, at its centroid)
        flags = list(s.flags)
        flags[K.F_CLUMPS] = True
        s.flags = tuple(flags)
        s.L = s.angmom_from_omega()
        n = len(s.rad)
        s.xs, s.vs, s.ws, s.fs, s.ts = (np.zeros((n, 3)) for _ in range(5))
        order = np.argsort(s.sbody, kind="stable")
        s.mstart = np.searchsorted(s.sbody[order], np.arange(nb + 1)).astype(np.int64)
        s.mlist = order.astype(np.int64)
        SphereShape._place_members(s)
        s.ws[:] = s.w[s.sbody]
        s.smass = np.ascontiguousarray(s.mass[s.sbody])
        # template tables, per-primitive template (-1 for spheres) and rows of the world arrays
        s.shapes = shape_tables(sh)
        s.shape = np.ascontiguousarray(np.concatenate([np.full(s.ns, -1, np.int64), s.pshape]))
        s.bvstart, s.bfstart, s.world = world_rows(s.shapes, s.shape)
        s.bonds = BondSet.empty(0)

    @staticmethod
    def body_of_primitive(s):
        return s.sbody

    # ---- the engine's tuples ----------------------------------------------------------
    @staticmethod
    def geometry(s):
        from demcli.kernels.shapes.mixed import MixedGeometry
        from demcli.kernels.shapes.polyhedra import PolyGeometry
        from demcli.kernels.shapes.spheres import SphereGeometry

        vs, verts, fs, fvs, fv, fn, fo = s.shapes
        return MixedGeometry(SphereGeometry(s.xs, s.vs, s.ws, s.rad, s.smat, s.smass, s.sbody, s.soff, None),
                             PolyGeometry(s.rad, s.smat, s.shape, vs, verts, fs, fvs, fv, fn, fo, s.bvstart,
                                          s.bfstart, *s.world, None), s.ns, s.qprm)

    @staticmethod
    def members(s):
        return K.Members(s.mstart, s.mlist, s.xs, s.fs, s.ts)

    @staticmethod
    def bond_arrays(s):
        return None, _empty2(N_BTABLE)

    @staticmethod
    def after_advance(s):
        pass

    @staticmethod
    def initial_lists(s, groups):
        """Contacts seeded with the stored ones (:meth:`groups` writes them by kind), as the other
        shapes do: history for carry-over, forces, depths and touching flags."""
        n = len(s.rad)
        cols = {"ft": (3, s.flags[K.F_FRICTION]), "mr": (3, s.flags[K.F_ROLLING]), "force": (3, True),
                "depth": (0, True), "box": (6, True)}
        pairs = _by_primitive(s, groups, (("contacts", "i", "j", 0, 0),
                                          ("sphere_body_contacts", "sphere", "body", 0, 1),
                                          ("body_contacts", "i", "j", 1, 1)))
        walls = _by_primitive(s, groups, (("wall_contacts", "sphere", "wall", 0, None),
                                          ("body_wall_contacts", "body", "wall", 1, None)))
        start, ci, cj, rows = stored_contacts(pairs, "a", "b", n, cols)
        wstart, wp, ww, wrows = stored_contacts(walls, "a", "b", n, cols, len(s.walls))
        return contacts_tuple(start, ci, cj, rows, wstart, wp, ww, wrows, s.xs.copy(), len(s.walls), True, True)

    # ---- measures -----------------------------------------------------------------------
    @staticmethod
    def critical_dt(s):
        """The smaller of the spheres' critical step (:func:`critical_time_step` over the sphere
        primitives; its linear-law bound takes the stiffest material pair, polyhedra included) and
        the polyhedra's (:meth:`PolyShape.critical_dt` of the polyhedral bodies)."""
        ns = s.ns
        dt = critical_time_step(s.model, s.prm, s.materials, s.mass, s.rad[:ns], s.sbody[:ns], s.smat[:ns])
        if s.model.law != "linear":
            dt *= math.sqrt(s.mass_scale)
        b = slice(s.nbs, None)
        poly = SimpleNamespace(mass=s.mass[b], inert=s.inert[b], bflags=s.bflags[b], shape=s.pshape,
                               bmat=s.bmat, prm=s.qprm, walls=s.walls, wmat=s.wmat, shapes=s.shapes,
                               _shape_group=s._shape_group)
        return min(float(dt), PolyShape.critical_dt(poly))

    @staticmethod
    def strain_energy(s):
        """Elastic energy of the contacts [J]: sphere and sphere-polyhedron contacts exactly,
        polyhedron contacts estimated (:func:`demcli.kernels.shapes.mixed.strain_energy_mixed`)."""
        from demcli.kernels.shapes.mixed import strain_energy_mixed
        from demcli.kernels.shapes.spheres import wall_strain_energy

        nl = s.nl
        w = s.walls
        friction, rolling = s.flags[K.F_FRICTION], s.flags[K.F_ROLLING]
        e = strain_energy_mixed(MixedShape.geometry(s), nl, s.prm, s.law, friction, rolling)
        return float(e + wall_strain_energy(s.xs[:s.ns], s.rad, s.smat, s.prm, s.law, nl.wstart, nl.wwall, w.kind,
                                            s.wpoint, w.normal, w.radius, s.wmat, nl.wft, nl.wmr, friction,
                                            rolling, s.wmesh))

    contact_count = staticmethod(SphereShape.contact_count)  # (pairs touching, wall contacts touching)

    @staticmethod
    def late_groups(s):
        return {}

    @staticmethod
    def groups(s):
        """spheres (the sphere primitives), polyhedra and polyhedron_shapes (passed through), and
        the touching contacts by kind: ``contacts`` (sphere pairs), ``sphere_body_contacts``
        (sphere, polyhedral body; force on the sphere), ``body_contacts`` (polyhedron pairs, with
        depth), ``wall_contacts`` (spheres), ``body_wall_contacts`` (polyhedra, with depth)."""
        from demcli.kernels.shapes.polyhedra import G_DEPTH

        nl = s.nl
        ns = s.ns
        friction, rolling = s.flags[K.F_FRICTION], s.flags[K.F_ROLLING]
        act = nl.act.astype(bool)
        wact = np.any(nl.wfc[:, :3] != 0.0, axis=1) if len(nl.wfc) else np.zeros(0, bool)
        pi, pj, wp = nl.pi, nl.pj, nl.wprim
        out = {"spheres": {"body": s.sbody[:ns].copy(), "offset": s.soff[:ns].copy(), "radius": s.rad[:ns].copy(),
                           "material": s.smat[:ns].copy()},
               "polyhedra": {k: v.copy() for k, v in s._poly_group.items()},
               "polyhedron_shapes": {k: v.copy() for k, v in s._shape_group.items()}}
        kinds = (("contacts", act & (pj < ns), ("i", pi), ("j", pj), False, rolling),
                 ("sphere_body_contacts", act & (pi < ns) & (pj >= ns), ("sphere", pi), ("body", s.sbody[pj]), False,
                  rolling),
                 ("body_contacts", act & (pi >= ns), ("i", s.sbody[pi]), ("j", s.sbody[pj]), True, False))
        for name, m, (ka, a), (kb, b), depth, mr in kinds:
            out[name] = _contact_rows(m, ka, a, kb, b, nl.fc, nl.geo[:, G_DEPTH] if depth else None,
                                      nl.ft if friction else None, nl.mr if mr else None)
        out["body_contacts"]["box"] = nl.pbox[act & (pi >= ns)].copy()
        wsph = wact & (wp < ns)
        wpol = wact & (wp >= ns)
        out["wall_contacts"] = _contact_rows(wsph, "sphere", wp, "wall", nl.wwall, nl.wfc[:, :3], None,
                                             nl.wft if friction else None, nl.wmr if rolling else None)
        out["body_wall_contacts"] = _contact_rows(wpol, "body", s.sbody[wp], "wall", nl.wwall, nl.wfc[:, :3],
                                                  nl.wgeo[:, G_DEPTH], nl.wft if friction else None, None)
        return out


def _contact_rows(mask, ka, a, kb, b, force, depth, ft, mr):
    """One contact group: the rows of ``mask`` (a, b indices, force, and depth, ft, mr where given)."""
    out = {ka: np.asarray(a)[mask].copy(), kb: np.asarray(b)[mask].copy(), "force": force[mask].copy()}
    for key, rows in (("depth", depth), ("ft", ft), ("mr", mr)):
        if rows is not None:
            out[key] = rows[mask].copy()
    return out


def _by_primitive(s, groups, kinds):
    """Stored contacts of several groups as one group of primitive indices a, b (a < b for pairs):
    kinds: (group, key a, key b, a is a body, b is a body (None: a wall index))."""
    prim_of_body = np.full(len(s.mass), -1, np.int64)
    prim_of_body[s.nbs:] = np.arange(s.ns, len(s.rad))
    parts = {"a": [], "b": [], "force": [], "depth": [], "ft": [], "mr": [], "box": []}
    for name, ka, kb, a_body, b_body in kinds:
        g = groups.get(name, {})
        a = np.asarray(g.get(ka, np.zeros(0, np.int64)), np.int64)
        b = np.asarray(g.get(kb, np.zeros(0, np.int64)), np.int64)
        parts["a"].append(prim_of_body[a] if a_body else a)
        parts["b"].append(b if b_body is None else prim_of_body[b] if b_body else b)
        for key, cols in (("force", 3), ("depth", 0), ("ft", 3), ("mr", 3), ("box", 6)):
            shape = (len(a), cols) if cols else (len(a),)
            parts[key].append(np.asarray(g[key], np.float64).reshape(shape) if key in g else np.zeros(shape))
    return {k: np.concatenate(v) for k, v in parts.items()}
