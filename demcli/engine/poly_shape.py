"""The polyhedron shape plug-in of :class:`demcli.engine.system.System`: rigid convex polyhedra.

Built from a state whose bodies are polyhedra (groups ``bodies``, ``polyhedra``,
``polyhedron_shapes``, see docs/polyhedra.md); the kernels are in
:mod:`demcli.kernels.shapes.polyhedra`. Contacts are stored in ``body_contacts`` and
``body_wall_contacts`` (with their depth).

Physics (seed 002, Shao, Lian & Yang 2017, sec. 3; details in the kernel module):
volumetric normal law F_N = k_n sqrt(V d), k_n = 4 E / (3 sqrt(pi)) with
E = 2 E1 E2 / (E1 + E2); incremental tangential spring K_t = 0.25 k_n sqrt(A_c) with
Coulomb slip (``friction`` effect); optional normal dashpot from the restitution
coefficient (effect ``contact_damping`` or ``contact_damping=True``); body damping:
``local_damping``, ``viscous_damping`` and the seed's adaptive alpha (effect
``adaptive_damping`` or ``adaptive_damping=True``). Walls: planes only.

The contact model's ``law``, ``kn``, ``kt``, ``cn`` do not apply (the law is fixed);
``pairs`` may override ``friction`` and ``restitution`` per material pair.
"""

import math

import numpy as np

from demcli.engine.bonds import BondSet
from demcli.engine.materials import damping_ratio
from demcli.engine.sphere_shape import _empty2, contacts_tuple, stored_contacts
from demcli.kernels import layout as K
from demcli.kernels.bonds import N_BTABLE
from demcli.kernels.shapes.polyhedra import BOX_COLS, LINEAR_COLS, Q_MU
from demcli.kernels.walls import MESH, PLANE

# bounding radius = template circumradius x (1 + BOUND_PAD): round-off of the world transform
# can never put a vertex outside the sphere the broad phase and the pair pass test
BOUND_PAD = 1e-12


def face_areas(shapes):
    """Area of every face of a ``polyhedron_shapes`` group [m^2] (body frame, fan triangles)."""
    v = np.asarray(shapes["vertices"], np.float64)
    fvs = np.asarray(shapes["face_vertex_start"], np.int64)
    fv = np.asarray(shapes["face_vertices"], np.int64)
    nf = len(fvs) - 1
    nt = np.diff(fvs) - 2                      # fan triangles (p0, p_k, p_k+1) per face
    face = np.repeat(np.arange(nf), nt)
    k = np.arange(int(nt.sum())) - np.repeat(np.cumsum(nt) - nt, nt) + 1
    base = fvs[face]
    p0 = v[fv[base]]
    s = np.zeros((nf, 3))
    np.add.at(s, face, np.cross(v[fv[base + k]] - p0, v[fv[base + k + 1]] - p0))
    return 0.5 * np.linalg.norm(s, axis=1)


def rotational_compliance(vertices, vertex_start, shape, inertia):
    """Largest (p x n) . I^-1 (p x n) of each body over its points p and unit vectors n [1/kg].

    vertices: (n_v, 3) template vertices [m] in the principal frame (centroid at the
    origin); vertex_start: (n_shape + 1,) CSR offsets into them; shape: (n,) template of
    each body; inertia: (n, 3) principal moments [kg m^2]. With [p]x the cross-product
    matrix (p x n = [p]x n), the maximum over n for one p is the largest eigenvalue of
    [p]x^T I^-1 [p]x; over p it is reached at a vertex, the function being a maximum of
    convex quadratics of p. See :meth:`PolyShape.critical_dt`.
    """
    counts = np.diff(vertex_start)[shape]
    body = np.repeat(np.arange(len(shape)), counts)
    rows = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(
        vertex_start[shape], counts)
    p = vertices[rows]
    z = np.zeros(len(p))
    px = np.stack([np.stack([z, -p[:, 2], p[:, 1]], 1), np.stack([p[:, 2], z, -p[:, 0]], 1),
                   np.stack([-p[:, 1], p[:, 0], z], 1)], 1)   # [p]x: [p]x n = p x n
    m = np.einsum("kji,kj,kjl->kil", px, 1.0 / inertia[body], px)
    out = np.zeros(len(shape))
    np.maximum.at(out, body, np.linalg.eigvalsh(m)[:, -1])
    return out


def poly_pair_table(materials, model):
    """(n_m, n_m, N_QPARAMS) table: k_n = 4 E / (3 sqrt(pi)) with E = 2 E1 E2 / (E1 + E2) (2 E1 on a rigid wall),
    friction (geometric mean) and the dashpot damping ratio from restitution (geometric
    mean), with the per-pair overrides of ``model.pairs`` (friction, restitution)."""
    from demcli.kernels.shapes.polyhedra import N_QPARAMS, Q_KN, Q_MU, Q_ZETA

    n = len(materials)
    prm = np.zeros((n, n, N_QPARAMS))
    names = [m.name for m in materials]
    overrides = {}
    for a, b, values in model.pairs:
        bad = sorted(set(values) - {"friction", "restitution"})
        if bad:
            raise ValueError(f"contact pair {a}-{b}: {bad} do not apply to polyhedra (volumetric law)")
        ia, ib = names.index(a), names.index(b)
        overrides[(ia, ib)] = overrides[(ib, ia)] = dict(values)
    for i, mi in enumerate(materials):
        for j, mj in enumerate(materials):
            o = overrides.get((i, j), {})
            if mi.rigid or mj.rigid:  # a rigid wall: 1/E = 1/(2 E1)
                e = math.inf if mi.rigid and mj.rigid else 2.0 * (mj.young if mi.rigid else mi.young)
            else:
                e = 2.0 * mi.young * mj.young / (mi.young + mj.young)
            prm[i, j, Q_KN] = 4.0 * e / (3.0 * math.sqrt(math.pi))
            prm[i, j, Q_MU] = o.get("friction", math.sqrt(mi.friction * mj.friction))
            prm[i, j, Q_ZETA] = damping_ratio(o.get("restitution", math.sqrt(mi.restitution * mj.restitution)))
    return prm


def _quat_from_matrix(rot):
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(rot).as_quat()
    return np.array([w, x, y, z])


def _quat_mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def polyhedra_groups(polys, density, x=None, q=None, v=None, omega=None, material=0, flags=None):
    """State groups (bodies, spheres, polyhedra, polyhedron_shapes) of ConvexPolyhedron bodies.

    polys: list of :class:`~demcli.geometry.ConvexPolyhedron` (coordinates in m).
    density: kg/m^3 (scalar or per body). x: (n, 3) centroid positions [m] (default:
    each polyhedron's own centroid, so the bodies sit where their coordinates say).
    q: (n, 4) extra rotations (w, x, y, z) applied about the centroid to the
    polyhedron as given (default none). v, omega: (n, 3) [m/s], [rad/s].
    material: index per body or scalar. flags: (n,) int8 FIX_* bits.
    The templates are stored in each body's principal frame; ``bodies/q`` is the
    rotation from that frame to the world.
    """
    from demcli.state.polyhedra import ShapeTable

    n = len(polys)
    table = ShapeTable.from_polyhedra(polys)
    rho = np.broadcast_to(np.asarray(density, np.float64), (n,))
    cen = np.array([p.centroid for p in polys]).reshape(n, 3)
    x = cen.copy() if x is None else np.asarray(x, np.float64).reshape(n, 3).copy()
    quats = np.empty((n, 4))
    for k, p in enumerate(polys):
        q0 = _quat_from_matrix(p.principal_axes)   # principal frame -> the polyhedron's frame
        qk = q0 if q is None else _quat_mul(np.asarray(q[k], np.float64) / np.linalg.norm(q[k]), q0)
        quats[k] = qk / np.linalg.norm(qk)
    bodies = {"x": x, "v": np.zeros((n, 3)) if v is None else np.asarray(v, np.float64).reshape(n, 3).copy(),
              "q": quats, "omega": np.zeros((n, 3)) if omega is None else
              np.asarray(omega, np.float64).reshape(n, 3).copy(),
              "mass": rho * table.volume, "inertia": rho[:, None] * table.inertia,
              "id": np.arange(n, dtype=np.int64),
              "flags": np.zeros(n, np.int8) if flags is None else np.asarray(flags, np.int8)}
    spheres = {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)), "radius": np.zeros(0),
               "material": np.zeros(0, np.int64)}
    polyhedra = {"shape": np.arange(n, dtype=np.int64),
                 "material": np.broadcast_to(np.asarray(material, np.int64), (n,)).copy(),
                 "size_class": np.full(n, -1, np.int64), "sieve_size": np.zeros(n),
                 "library_index": np.full(n, -1, np.int64), "flaky": np.zeros(n, bool),
                 "elongated": np.zeros(n, bool)}
    return {"bodies": bodies, "spheres": spheres, "polyhedra": polyhedra, "polyhedron_shapes": table.to_group()}


def shape_tables(sh):
    """The polyhedron_shapes CSR tables as the kernels take them (body frame): (vertex_start,
    vertices, face_start, face_vertex_start, face_vertices, face_normal, face_offset)."""
    return (np.ascontiguousarray(sh["vertex_start"], np.int64), np.ascontiguousarray(sh["vertices"], np.float64),
            np.ascontiguousarray(sh["face_start"], np.int64), np.ascontiguousarray(sh["face_vertex_start"], np.int64),
            np.ascontiguousarray(sh["face_vertices"], np.int64), np.ascontiguousarray(sh["face_normal"], np.float64),
            np.ascontiguousarray(sh["face_offset"], np.float64))


def world_rows(shapes, shape):
    """(bvstart, bfstart, (wvert, wnorm, woff, travel)): each row's slice of the world vertex and
    face arrays for the templates ``shape`` (-1: a row without vertices, a sphere of a mixed
    scene), and the rows' travel (zeros, see :class:`demcli.kernels.shapes.polyhedra.PolyGeometry`)."""
    vs, fs = shapes[0], shapes[2]
    has = shape >= 0
    nv = np.zeros(len(shape), np.int64)
    nf = np.zeros(len(shape), np.int64)
    nv[has] = np.diff(vs)[shape[has]]
    nf[has] = np.diff(fs)[shape[has]]
    bvstart = np.zeros(len(shape) + 1, np.int64)
    bfstart = np.zeros(len(shape) + 1, np.int64)
    bvstart[1:] = np.cumsum(nv)
    bfstart[1:] = np.cumsum(nf)
    return bvstart, bfstart, (np.zeros((int(bvstart[-1]), 3)), np.zeros((int(bfstart[-1]), 3)),
                              np.zeros(int(bfstart[-1])), np.zeros(len(shape)))


class PolyShape:
    """Convex polyhedra: sets the system's polyhedron arrays and gives the engine their tuples.

    The contact model's ``law``, ``kn``, ``kt``, ``cn`` do not apply (the law is fixed);
    ``pairs`` may override ``friction`` and ``restitution`` per material pair. Walls: planes.
    """

    name = "polyhedra"
    MUTABLE = ()
    FRICTION = Q_MU  # column of prm with the friction coefficient

    def __init__(self, s, groups):
        if len(s.walls) and np.any(np.isin(np.asarray(s.walls.kind), (PLANE, MESH), invert=True)):
            bad = [s.walls.name[k] for k in range(len(s.walls)) if s.walls.kind[k] not in (PLANE, MESH)]
            raise ValueError(f"polyhedra support plane and mesh walls only; not {bad}")
        s.law = 0
        s.prm = poly_pair_table(s.materials, s.model)
        ph = groups["polyhedra"]
        sh = groups["polyhedron_shapes"]
        s._poly_group = {k: np.asarray(val) for k, val in ph.items()}
        s._shape_group = {k: np.asarray(val) for k, val in sh.items()}
        s._spheres_group = groups.get("spheres", {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)),
                                                  "radius": np.zeros(0), "material": np.zeros(0, np.int64)})
        s.clumps = False
        s.L = s.angmom_from_omega()
        # shapes (body-frame CSR tables, used as they are) and per-body rows of the world arrays
        s.shape = np.ascontiguousarray(ph["shape"], np.int64)
        s.bmat = np.ascontiguousarray(ph["material"], np.int64)
        s.shapes = shape_tables(sh)
        s.bvstart, s.bfstart, s.world = world_rows(s.shapes, s.shape)
        s.rad = np.ascontiguousarray(np.asarray(sh["radius"], np.float64)[s.shape] * (1.0 + BOUND_PAD))
        s.xs = s.x  # the bodies are the particles: the dem stage measures the scene through xs
        s.bonds = BondSet.empty(0)

    @staticmethod
    def body_of_primitive(s):
        return np.arange(len(s.mass))

    # ---- the engine's tuples ----------------------------------------------------------
    @staticmethod
    def geometry(s):
        from demcli.kernels.shapes.polyhedra import PolyGeometry

        vs, verts, fs, fvs, fv, fn, fo = s.shapes
        return PolyGeometry(s.rad, s.bmat, s.shape, vs, verts, fs, fvs, fv, fn, fo, s.bvstart, s.bfstart,
                            *s.world, s.model.geometry_refresh if s.model.geometry_refresh > 1 else None)

    @staticmethod
    def members(s):
        """None: every polyhedron is its own primitive (no member pass is compiled)."""
        return None

    @staticmethod
    def bond_arrays(s):
        """No bonds between polyhedra: (None, an empty model table)."""
        return None, _empty2(N_BTABLE)

    @staticmethod
    def after_advance(s):
        pass

    @staticmethod
    def initial_lists(s, groups):
        """Contacts seeded with the stored contacts: their history for carry-over, and their
        forces, depths and touching flags, so that :meth:`groups` of a system not yet stepped
        gives back the stored contacts (a stage resumed from a checkpoint of its last step). A
        state written before contacts kept their depth seeds depth 0 (such a contact counts
        again once the resumed stage has stepped)."""
        nb = len(s.mass)
        linear = s.model.geometry_refresh > 1
        cols = {"ft": (3, s.flags[K.F_FRICTION]), "mr": (3, False), "force": (3, True), "depth": (0, True),
                "box": (BOX_COLS, True), "linearized": (LINEAR_COLS - BOX_COLS, linear)}
        start, ci, cj, rows = stored_contacts(groups.get("body_contacts", {}), "i", "j", nb, cols)
        if linear:  # the kept exact evaluations beside the boxes (kernels.shapes.polyhedra.L_*)
            rows["box"] = np.hstack([rows["box"], rows.pop("linearized")])
        wstart, wb, ww, wrows = stored_contacts(groups.get("body_wall_contacts", {}), "body", "wall", nb, cols,
                                                len(s.walls))
        return contacts_tuple(start, ci, cj, rows, wstart, wb, ww, wrows, s.x.copy(), len(s.walls), True, True)

    @staticmethod
    def critical_dt(s):
        """Critical time step of this scene [s]: 2 / omega_max over the mobile bodies.

        A normal force F n at the point p of a body (p from its centroid, m) accelerates
        that point along n by F (1/m + (p x n) . I^-1 (p x n)): n . (F n / m +
        (I^-1 (p x F n)) x p), rotation included. A contact of normal stiffness K [N/m]
        between two bodies is thus a spring on the effective mass m_eff,
        1/m_eff = sum over the two bodies of 1/m + (p x n) . I^-1 (p x n) [1/kg], and
        omega^2 = K / m_eff. Each body is bounded with itself as the partner (two equal
        bodies):

            omega^2 = 2 K_max (1/m + c_rot)

        * K_max = k_n sqrt(A_f) [N/m]: the stiffest contact the body can make, a whole
          face on a face (the volumetric law's stiffness for a flat overlap of area A is
          k_n sqrt(A)); A_f the body's largest face area, k_n that of its stiffest
          partner material, walls included.
        * c_rot [1/kg]: the largest (p x n) . I^-1 (p x n) over the body's points and
          directions (:func:`rotational_compliance`). A sliver touched at an edge,
          r = t / sqrt 2 from its axis, I = m t^2 / 6 about it, moves like a quarter of
          its mass (3/m); over its whole surface c_rot = 6/m. With the translational
          mass alone (c_rot = 0) a sliver struck between two plates went unstable at
          dt = 0.3 x that step with the normal dashpot and local damping
          (docs/stability.md).

        The bound pairs the stiffest contact (a whole face) with the most compliant
        point (a vertex), which no single contact is: a whole face's overlap has its
        centroid near the face's centre. For a cube, a square patch of side s a in a
        corner of a face gives omega^2 = 2 k_n sqrt(A_f) s (1 + 3 (1 - s)^2) / m, never
        above the face-on value (s = 1), while the bound is 5.5 times it (dt / 2.3); a
        40 x 40 x 2 mm plate and a 40 x 2 x 2 mm sliver get dt / 2.6 and random ballast
        stones dt / 2.3 .. 3.4. The margin is what covers several contacts on one body
        acting in a shared mode (the pinched sliver) and the damping.
        """
        from demcli.kernels.shapes.polyhedra import Q_KN

        nb = len(s.mass)
        if nb == 0:
            return math.inf
        fa = face_areas(s._shape_group)
        fs = s.shapes[2]
        amax = np.array([fa[fs[k]:fs[k + 1]].max() for k in range(len(fs) - 1)])[s.shape]
        kn = s.prm[..., Q_KN]
        # stiffest partner material of each body (walls included)
        mats = np.unique(np.concatenate([s.bmat, s.wmat]))
        knb = kn[s.bmat][:, mats].max(axis=1)
        crot = rotational_compliance(s.shapes[1], s.shapes[0], s.shape, s.inert)
        crot[(s.bflags & K.FIX_ROTATION) != 0] = 0.0
        w2 = 2.0 * knb * np.sqrt(amax) * (1.0 / s.mass + crot)
        mobile = (s.bflags & K.FIX_TRANSLATION) == 0
        if not mobile.any():
            return math.inf
        return 2.0 / math.sqrt(float(w2[mobile].max()))

    @staticmethod
    def strain_energy(s):
        """Elastic energy of the contacts [J], estimated: the volumetric law has no potential in
        general (see :func:`demcli.kernels.shapes.polyhedra.strain_energy_estimate`); F_N d / 2 per
        contact (exact for flat face-face overlaps) plus |F_s|^2 / (2 K_t)."""
        from demcli.kernels.shapes.polyhedra import strain_energy_estimate

        nl = s.nl
        return float(strain_energy_estimate(nl.act, nl.geo, nl.ft, nl.wgeo, nl.wft, s.flags[K.F_FRICTION]))

    @staticmethod
    def contact_count(s):
        """(body-body contacts, body-wall contacts) touching at the last evaluation."""
        nl = s.nl
        return int(nl.act.sum()), int(np.count_nonzero(nl.wgeo[:, 0] > 0.0)) if len(nl.wgeo) else 0

    @staticmethod
    def touching_pairs(s):
        """(i, j) body indices of the pairs touching now."""
        act = s.nl.act.astype(bool)
        return np.asarray(s.nl.pi[act], np.int64), np.asarray(s.nl.pj[act], np.int64)

    @staticmethod
    def touching_walls(s):
        """(body, wall) of the body-wall contacts touching now (a positive depth)."""
        from demcli.kernels.shapes.polyhedra import G_DEPTH

        nl = s.nl
        wact = nl.wgeo[:, G_DEPTH] > 0.0 if len(nl.wgeo) else np.zeros(0, bool)
        return np.asarray(nl.wprim[wact], np.int64), np.asarray(nl.wwall[wact], np.int64)

    @staticmethod
    def late_groups(s):
        return {}

    @staticmethod
    def groups(s):
        """spheres (empty), polyhedra and polyhedron_shapes (passed through), body_contacts (i, j
        body indices, i < j, force on i, depth, ft with friction), body_wall_contacts (body, wall,
        force, depth, ft)."""
        from demcli.kernels.shapes.polyhedra import G_DEPTH

        nl = s.nl
        act = nl.act.astype(bool)
        contacts = {"i": nl.pi[act].copy(), "j": nl.pj[act].copy(), "force": nl.fc[act].copy(),
                    "depth": nl.geo[act, G_DEPTH].copy(), "box": nl.pbox[act, :BOX_COLS].copy()}
        if nl.pbox.shape[1] > BOX_COLS:
            contacts["linearized"] = nl.pbox[act, BOX_COLS:].copy()
        if s.flags[K.F_FRICTION]:
            contacts["ft"] = nl.ft[act].copy()
        wgeo = nl.wgeo
        wact = wgeo[:, G_DEPTH] > 0.0 if len(wgeo) else np.zeros(0, bool)
        wall_contacts = {"body": nl.wprim[wact].copy(), "wall": nl.wwall[wact].copy(),
                         "force": nl.wfc[wact, :3].copy(), "depth": wgeo[wact, G_DEPTH].copy()}
        if s.flags[K.F_FRICTION]:
            wall_contacts["ft"] = nl.wft[wact].copy()
        return {"spheres": {k: np.asarray(v).copy() for k, v in s._spheres_group.items()},
                "polyhedra": {k: v.copy() for k, v in s._poly_group.items()},
                "polyhedron_shapes": {k: v.copy() for k, v in s._shape_group.items()},
                "body_contacts": contacts, "body_wall_contacts": wall_contacts}
