"""A scene of rigid convex polyhedra in memory: the polyhedral counterpart of :class:`System`.

:class:`PolySystem` has the public interface of :class:`demcli.engine.system.System`
(constructor, attributes, ``advance``, measures, ``snapshot``/``restore``,
``groups``), so the ``dem`` stage can drive either. It is built from a state whose
bodies are polyhedra (groups ``bodies``, ``polyhedra``, ``polyhedron_shapes``, see
docs/polyhedra.md) and runs :func:`demcli.kernels.poly_step.run_poly_steps`.

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

from demcli.engine.materials import damping_ratio
from demcli.engine.system import BodySystem
from demcli.kernels import layout as K
from demcli.kernels.walls import PLANE

_EMPTY_I = np.empty(0, np.int64)

# bounding radius = template circumradius x (1 + BOUND_PAD): round-off of the world transform
# can never put a vertex outside the sphere the broad phase and the pair pass test
BOUND_PAD = 1e-12
# adaptive damping: initial alpha (seed: 0.1 1/s) and the clamps (see PolySystem)
ALPHA0 = 0.1


def _empty2(cols):
    return np.zeros((0, cols))


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
    convex quadratics of p. See :meth:`PolySystem.critical_dt`.
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
    """(n_m, n_m, N_QPARAMS) table: k_n = 4 E / (3 sqrt(pi)) with E = 2 E1 E2 / (E1 + E2),
    friction (geometric mean) and the dashpot damping ratio from restitution (geometric
    mean), with the per-pair overrides of ``model.pairs`` (friction, restitution)."""
    from demcli.kernels.poly_step import N_QPARAMS, Q_KN, Q_MU, Q_ZETA

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


def actor_loads(actors, nb):
    """(bload (n_b, N_LOAD), nsmall) of the ``actors`` group (see docs/state.md).

    Actors (loading plate, sleeper) must be the last bodies: the particles
    0..nsmall-1 go through the cell grid, the actors are paired by
    :func:`demcli.kernels.poly_step.add_actor_pairs`.
    """
    from demcli.kernels.poly_step import L_F0, L_F1, L_OMEGA, L_PHASE, L_T0, N_LOAD

    bload = np.zeros((nb, N_LOAD))
    body = np.asarray(actors.get("body", _EMPTY_I), np.int64)
    if len(body) == 0:
        return bload, nb
    nsmall = int(body.min())
    if sorted(body.tolist()) != list(range(nsmall, nb)):
        raise ValueError(f"actors must be the last bodies of the scene; got bodies {body.tolist()} of {nb}")
    for k, b in enumerate(body):
        bload[b, L_F0:L_F0 + 3] = actors["load_mean"][k]
        bload[b, L_F1:L_F1 + 3] = actors["load_amplitude"][k]
        bload[b, L_OMEGA] = 2.0 * math.pi * float(actors["frequency"][k])
        bload[b, L_PHASE] = float(actors["phase"][k])
        bload[b, L_T0] = float(actors["start"][k])
    return bload, nsmall


class PolySystem(BodySystem):
    """Arrays and kernels of one stage whose bodies are rigid convex polyhedra.

    Args:
        groups: state groups ``bodies``, ``polyhedra``, ``polyhedron_shapes`` and
            optional ``contacts`` (i, j body indices, ft), ``wall_contacts`` (sphere =
            body index, wall, ft), ``energy``, ``adaptive_damping`` (alpha, ke_prev).
        materials: list of :class:`~demcli.engine.materials.Material`.
        model: :class:`~demcli.engine.materials.ContactModel` (only ``pairs`` used).
        plan: :class:`~demcli.engine.plan.Plan` (effects gravity, friction,
            local_damping, viscous_damping, energy, walls; ``contact_damping`` and
            ``adaptive_damping`` once registered).
        walls: :class:`~demcli.engine.system.Walls` (planes only).
        dynamics: :class:`~demcli.engine.system.Dynamics`; ``skin`` is a fraction of
            the mean bounding radius, ``overlap_limit`` bounds depth / bounding radius.
        dt: time step [s]. time, step: clock of the input state.
        contact_damping, adaptive_damping: switch those effects on without a plan
            entry (None: from the plan).
        alpha0: initial adaptive alpha [1/s] (seed: 0.1).
        mass_scale: mass scaling for quasi-static runs: masses and inertias are
            multiplied by it inside the engine and gravity divided by it (weights stay
            real, the critical step grows by its square root); ``groups()`` gives the
            real masses back. A power of 2 keeps the round trip exact.
        alpha_bounds: (min, max) of alpha as multiples of alpha0 and of 1/dt:
            alpha in [alpha0 x min, max / dt]. The seed's rule is unbounded; the floor
            keeps alpha from decaying towards zero during a long quiet phase (0.99^n)
            so that it can react within tens of steps, the ceiling keeps the damping
            factor (1 - alpha dt/4)/(1 + alpha dt/4) of a half kick positive.
    """

    def __init__(self, groups, materials, model, plan, walls, dynamics, dt, time=0.0, step=0,
                 contact_damping=None, adaptive_damping=None, alpha0=ALPHA0, alpha_bounds=(1e-3, 1.0),
                 mass_scale=1.0):
        from demcli.kernels.poly_step import (A_ALPHA, A_KE, A_MAX, A_MIN, N_ADAMP, N_SWITCHES, S_ADAPTIVE,
                                              S_DASHPOT, S_ENERGY, S_FRICTION, S_GRAVITY, S_LOCAL, S_VISCOUS,
                                              S_WALLS)

        for name in ("rolling_resistance", "planar", "clumps"):
            if plan.has(name):
                raise ValueError(f"effect {name!r} is not available for polyhedra")
        if len(walls) and np.any(np.asarray(walls.kind) != PLANE):
            bad = [walls.name[k] for k in range(len(walls)) if walls.kind[k] != PLANE]
            raise ValueError(f"polyhedra support plane walls only; not {bad}")
        self.plan = plan
        self.materials = list(materials)
        self.model = model
        self.walls = walls
        self.dyn = dynamics
        self.dt = float(dt)
        self.time = float(time)
        self.step = int(step)
        self.flags = plan.flags
        self.prm = poly_pair_table(self.materials, model)
        b = groups["bodies"]
        ph = groups["polyhedra"]
        sh = groups["polyhedron_shapes"]
        self._poly_group = {k: np.asarray(val) for k, val in ph.items()}
        self._shape_group = {k: np.asarray(val) for k, val in sh.items()}
        self._spheres_group = groups.get("spheres", {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)),
                                                     "radius": np.zeros(0), "material": np.zeros(0, np.int64)})
        self.body_id = np.ascontiguousarray(b["id"], np.int64)
        self.x = np.ascontiguousarray(b["x"], np.float64).copy()
        self.v = np.ascontiguousarray(b["v"], np.float64).copy()
        self.w = np.ascontiguousarray(b["omega"], np.float64).copy()
        self.q = np.ascontiguousarray(b["q"], np.float64).copy()
        qn = np.linalg.norm(self.q, axis=1)
        off = np.abs(qn - 1.0) > 1e-12  # renormalize only what is off (a resumed state stays bit-exact)
        self.q[off] /= qn[off, None]
        self.mass_scale = float(mass_scale)
        self.mass = np.ascontiguousarray(b["mass"], np.float64) * self.mass_scale
        self.inert = np.ascontiguousarray(b["inertia"], np.float64) * self.mass_scale
        self.bflags = np.ascontiguousarray(b["flags"], np.int8)
        nb = len(self.mass)
        self.f = np.ascontiguousarray(b.get("force", np.zeros((nb, 3))), np.float64).copy()
        self.tq = np.ascontiguousarray(b.get("torque", np.zeros((nb, 3))), np.float64).copy()
        self.L = (np.ascontiguousarray(b["angmom"], np.float64) * self.mass_scale if "angmom" in b
                  else self._angmom_from_omega())
        # shapes (body-frame CSR tables, used as they are) and per-body rows of the world arrays
        self.shape = np.ascontiguousarray(ph["shape"], np.int64)
        self.bmat = np.ascontiguousarray(ph["material"], np.int64)
        vs = np.ascontiguousarray(sh["vertex_start"], np.int64)
        fs = np.ascontiguousarray(sh["face_start"], np.int64)
        self.shapes = (vs, np.ascontiguousarray(sh["vertices"], np.float64), fs,
                       np.ascontiguousarray(sh["face_vertex_start"], np.int64),
                       np.ascontiguousarray(sh["face_vertices"], np.int64),
                       np.ascontiguousarray(sh["face_normal"], np.float64),
                       np.ascontiguousarray(sh["face_offset"], np.float64))
        nv = np.diff(vs)[self.shape]
        nf = np.diff(fs)[self.shape]
        self.bvstart = np.zeros(nb + 1, np.int64)
        self.bfstart = np.zeros(nb + 1, np.int64)
        self.bvstart[1:] = np.cumsum(nv)
        self.bfstart[1:] = np.cumsum(nf)
        self.world = (np.zeros((int(self.bvstart[-1]), 3)), np.zeros((int(self.bfstart[-1]), 3)),
                      np.zeros(int(self.bfstart[-1])))
        self.rad = np.ascontiguousarray(np.asarray(sh["radius"], np.float64)[self.shape] * (1.0 + BOUND_PAD))
        self._actors = {k: np.asarray(val) for k, val in groups.get("actors", {}).items()}
        self.bload, self.nsmall = actor_loads(self._actors, nb)
        self.xs = self.x  # the dem stage measures the scene through xs (bodies are the particles here)
        # walls
        self.wforce = np.zeros((len(walls), 3))
        self.wkn = np.zeros(len(walls))
        self.wpoint = np.ascontiguousarray(walls.point, np.float64).copy()
        self.wpoint0 = self.wpoint.copy()
        self.wv = np.ascontiguousarray(walls.v, np.float64).copy()
        # switches
        cd = plan.has("contact_damping") if contact_damping is None else bool(contact_damping)
        ad = plan.has("adaptive_damping") if adaptive_damping is None else bool(adaptive_damping)
        sw = [False] * N_SWITCHES
        sw[S_FRICTION] = plan.has("friction")
        sw[S_ENERGY] = plan.has("energy")
        sw[S_GRAVITY] = plan.has("gravity")
        sw[S_LOCAL] = plan.has("local_damping")
        sw[S_VISCOUS] = plan.has("viscous_damping")
        sw[S_DASHPOT] = cd
        sw[S_ADAPTIVE] = ad
        sw[S_WALLS] = len(walls) > 0
        self.sw = tuple(sw)
        self.contact_damping = cd
        self.adaptive_damping = ad
        energy = sw[S_ENERGY]
        eg = groups.get("energy", {})
        self.esph = np.zeros((nb if energy else 0, 2))
        self.ebody = np.zeros(nb if energy else 0)
        self.eacc = np.zeros(1)
        self.losses0 = {k: float(np.asarray(eg.get(k, 0.0))) for k in ("damping", "friction", "body_damping",
                                                                       "wall_work")}
        self.alpha0 = float(alpha0)
        self.alpha_bounds = tuple(float(a) for a in alpha_bounds)
        self.adamp = np.zeros(N_ADAMP)
        ag = groups.get("adaptive_damping", {})
        self.adamp[A_ALPHA] = float(np.asarray(ag.get("alpha", alpha0)))
        self.adamp[A_KE] = float(np.asarray(ag.get("ke_prev", self.kinetic_energy())))
        self.adamp[A_MIN] = self.alpha0 * self.alpha_bounds[0]
        self.adamp[A_MAX] = math.inf
        self.counters = np.zeros(K.N_COUNTERS, np.int64)
        self.info = np.zeros(4)
        self.nl = self._initial_lists(groups)
        self.skin = self.dyn.skin * float(self.rad.mean()) if nb else 0.0
        self.max_cells = max(64, 8 * nb)
        self._fresh_lists = True
        self.prime = True  # evaluate F(x_0) before the first step; False when resuming from stored loads
        self.gravity = np.asarray(dynamics.gravity, np.float64) / self.mass_scale
        self.ke_limit = math.inf

    # ---- set-up helpers -------------------------------------------------------------
    def _initial_lists(self, groups):
        """Neighbour state seeded with the stored contacts: their history for carry-over, and
        their forces, depths and touching flags, so that :meth:`groups` of a system not yet
        stepped gives back the stored contacts (a stage resumed from a checkpoint of its last
        step)."""
        from demcli.kernels.poly_step import G_DEPTH

        nb = len(self.mass)
        start, ci, cj, ft, fc, depth = self._stored_history(groups.get("body_contacts", {}), "i", "j", nb)
        wstart, wb, ww, wft, wf, wdepth = self._stored_history(groups.get("body_wall_contacts", {}), "body", "wall",
                                                               nb)
        npair = len(ci)
        nq = len(ww)
        geo = np.zeros((npair, 3))
        geo[:, G_DEPTH] = depth
        wfc = np.zeros((nq, 4))
        wfc[:, :3] = wf
        wgeo = np.zeros((nq, 3))
        wgeo[:, G_DEPTH] = wdepth
        return (start, ci, cj, np.zeros(nb + 1, np.int64), _EMPTY_I, ft, fc,
                np.zeros((npair, 3)), np.ones(npair, np.uint8), _empty2(2), geo,
                wstart, wb, ww, wft, wfc, wgeo,
                self.x.copy(), np.zeros((len(self.walls), 3)), np.zeros(npair, np.int32),
                np.zeros((npair, 3)))

    def _stored_history(self, group, key_a, key_b, n):
        """(CSR start, a, b, ft, force, depth) of stored contacts sorted by (a, b) (the kernels'
        canonical order); ft only with friction. A state written before contacts kept their
        depth seeds depth 0 (such a contact counts again once the resumed stage has stepped)."""
        a = np.asarray(group.get(key_a, _EMPTY_I), np.int64)
        b = np.asarray(group.get(key_b, _EMPTY_I), np.int64)
        order = np.lexsort((b, a))
        a, b = np.ascontiguousarray(a[order]), np.ascontiguousarray(b[order])
        start = np.searchsorted(a, np.arange(n + 1)).astype(np.int64)
        rows = {}
        for name, cols in (("ft", 3), ("force", 3), ("depth", 0)):
            shape = (len(a), cols) if cols else (len(a),)
            rows[name] = np.ascontiguousarray(np.asarray(group[name], np.float64)[order]) if name in group \
                else np.zeros(shape)
        ft = rows["ft"] if self.plan.has("friction") else _empty2(3)
        return start, a, b, ft, rows["force"], rows["depth"]

    # ---- time stepping --------------------------------------------------------------
    @property
    def alpha(self):
        """Current adaptive damping coefficient alpha [1/s] (seed eqs. 23-27)."""
        from demcli.kernels.poly_step import A_ALPHA

        return float(self.adamp[A_ALPHA])

    @alpha.setter
    def alpha(self, value):
        from demcli.kernels.poly_step import A_ALPHA

        self.adamp[A_ALPHA] = float(value)

    def critical_dt(self):
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
        from demcli.kernels.poly_step import Q_KN

        nb = len(self.mass)
        if nb == 0:
            return math.inf
        fa = face_areas(self._shape_group)
        fs = self.shapes[2]
        amax = np.array([fa[fs[k]:fs[k + 1]].max() for k in range(len(fs) - 1)])[self.shape]
        kn = self.prm[..., Q_KN]
        # stiffest partner material of each body (walls included)
        mats = np.unique(np.concatenate([self.bmat, np.asarray(self.walls.material, np.int64)]))
        knb = kn[self.bmat][:, mats].max(axis=1)
        crot = rotational_compliance(self.shapes[1], self.shapes[0], self.shape, self.inert)
        crot[(self.bflags & K.FIX_ROTATION) != 0] = 0.0
        w2 = 2.0 * knb * np.sqrt(amax) * (1.0 / self.mass + crot)
        mobile = (self.bflags & K.FIX_TRANSLATION) == 0
        if not mobile.any():
            return math.inf
        return 2.0 / math.sqrt(float(w2[mobile].max()))

    @staticmethod
    def step_kernel():
        """The compiled step loop :meth:`advance` calls (numba dispatcher)."""
        from demcli.kernels.poly_step import run_poly_steps

        return run_poly_steps

    def advance(self, nsteps):
        """Run ``nsteps`` steps in compiled code; returns (status, steps done)."""
        from demcli.kernels.poly_step import A_MAX, run_poly_steps

        self.adamp[A_MAX] = self.alpha_bounds[1] / self.dt if self.dt > 0 else math.inf
        w = self.walls
        status, done, self.time, self.nl = run_poly_steps(
            int(nsteps), self.time, self.dt, self.sw, self.prm, self.gravity,
            float(self.dyn.local_damping), float(self.dyn.viscous_damping), self.adamp,
            (self.x, self.v, self.w, self.q, self.L, self.f, self.tq), self.mass, self.inert, self.bflags,
            self.rad, self.bmat, self.shapes, self.shape, self.bvstart, self.bfstart, self.world,
            np.ascontiguousarray(w.kind, np.int8), self.wpoint, np.ascontiguousarray(w.normal, np.float64),
            self.wv, np.ascontiguousarray(w.material, np.int64), np.ascontiguousarray(w.control, np.int8),
            np.ascontiguousarray(w.prm, np.float64), self.wforce, self.wkn,
            self.nl, self.skin, self.max_cells,
            self.esph, self.ebody, self.eacc,
            int(self.dyn.check_every), float(self.dyn.overlap_limit), float(self.ke_limit),
            self.counters, self.info, self._fresh_lists, self.step, self.prime, self.bload, self.nsmall)
        self._fresh_lists = False
        self.prime = False
        self.step += int(done)
        return int(status), int(done)

    def set_actor_start(self, name, t0):
        """Start time [s] of the oscillating load of the actor ``name``."""
        from demcli.kernels.poly_step import L_T0

        names = [n.decode() if isinstance(n, bytes) else str(n) for n in self._actors["name"]]
        k = names.index(name)
        self._actors["start"] = self._actors["start"].astype(np.float64)
        self._actors["start"][k] = t0
        self.bload[int(self._actors["body"][k]), L_T0] = t0

    # ---- measures -------------------------------------------------------------------
    def strain_energy(self):
        """Elastic energy of the contacts [J], estimated: the volumetric law has no
        potential in general (see :func:`demcli.kernels.poly_step.strain_energy_estimate`);
        F_N d / 2 per contact (exact for flat face-face overlaps) plus |F_s|^2 / (2 K_t)."""
        from demcli.kernels.poly_step import P_ACT, P_FT, P_GEO, P_WFT, P_WGEO, strain_energy_estimate

        nl = self.nl
        return float(strain_energy_estimate(nl[P_ACT], nl[P_GEO], nl[P_FT], nl[P_WGEO], nl[P_WFT],
                                            self.plan.has("friction")))

    def contact_count(self):
        """(body-body contacts, body-wall contacts) touching at the last evaluation."""
        from demcli.kernels.poly_step import P_ACT, P_WGEO

        nl = self.nl
        wgeo = nl[P_WGEO]
        return int(nl[P_ACT].sum()), int(np.count_nonzero(wgeo[:, 0] > 0.0)) if len(wgeo) else 0

    # ---- state exchange -------------------------------------------------------------
    rotation_from_angmom = True  # polyhedra have general inertia tensors

    _MUTABLE = ("x", "v", "w", "q", "L", "f", "tq", "wpoint", "wv", "wforce", "esph", "ebody", "eacc", "adamp",
                "nl", "time", "step")

    def groups(self):
        """State groups of the current scene.

        bodies (with force, torque, angmom), spheres (empty), polyhedra and
        polyhedron_shapes (passed through), contacts (i, j body indices, i < j, force on
        i, ft with friction), wall_contacts (sphere = the body index, wall, force, ft),
        walls, energy, and adaptive_damping (alpha, ke_prev) when that effect is on.
        """
        from demcli.kernels.poly_step import A_ALPHA, A_KE, G_DEPTH, P_ACT, P_FC, P_FT, P_GEO, P_PI, P_PJ, P_WBODY, \
            P_WFC, P_WFT, P_WGEO, P_WWALL

        nl = self.nl
        act = nl[P_ACT].astype(bool)
        contacts = {"i": nl[P_PI][act].copy(), "j": nl[P_PJ][act].copy(), "force": nl[P_FC][act].copy(),
                    "depth": nl[P_GEO][act, G_DEPTH].copy()}
        if self.plan.has("friction"):
            contacts["ft"] = nl[P_FT][act].copy()
        wgeo = nl[P_WGEO]
        wact = wgeo[:, G_DEPTH] > 0.0 if len(wgeo) else np.zeros(0, bool)
        wall_contacts = {"body": nl[P_WBODY][wact].copy(), "wall": nl[P_WWALL][wact].copy(),
                         "force": nl[P_WFC][wact, :3].copy(), "depth": wgeo[wact, G_DEPTH].copy()}
        if self.plan.has("friction"):
            wall_contacts["ft"] = nl[P_WFT][wact].copy()
        bodies = {"x": self.x.copy(), "v": self.v.copy(), "q": self.q.copy(), "omega": self.w.copy(),
                  "mass": self.mass / self.mass_scale, "inertia": self.inert / self.mass_scale,
                  "id": self.body_id.copy(), "flags": self.bflags.copy(), "force": self.f.copy(),
                  "torque": self.tq.copy(), "angmom": self.L / self.mass_scale}
        w = self.walls
        walls = {"name": np.array(w.name, dtype=object), "kind": np.asarray(w.kind).copy(),
                 "point": self.wpoint.copy(), "normal": np.asarray(w.normal).copy(),
                 "radius": np.asarray(w.radius).copy(), "v": self.wv.copy(), "material": np.asarray(w.material).copy(),
                 "control": np.asarray(w.control).copy(), "target": np.asarray(w.prm)[:, 0].copy(),
                 "force": self.wforce.copy(), "extent": np.asarray(w.extent) + np.tile(self.wpoint - self.wpoint0, 2)}
        energy = {k: np.float64(v) for k, v in self.losses().items()}
        out = {"bodies": bodies, "spheres": {k: np.asarray(v).copy() for k, v in self._spheres_group.items()},
               "polyhedra": {k: v.copy() for k, v in self._poly_group.items()},
               "polyhedron_shapes": {k: v.copy() for k, v in self._shape_group.items()},
               "body_contacts": contacts, "body_wall_contacts": wall_contacts, "walls": walls, "energy": energy}
        if len(self._actors):
            out["actors"] = {k: v.copy() for k, v in self._actors.items()}
        if self.adaptive_damping:
            out["adaptive_damping"] = {"alpha": np.float64(self.adamp[A_ALPHA]),
                                       "ke_prev": np.float64(self.adamp[A_KE])}
        return out
