"""A scene in memory: structure-of-arrays state, plan, and the one compiled step loop.

:class:`System` is built from a state's groups (see docs/state.md), a stage's contact
model, effects and walls, for any body shape: the shape plug-in (``SphereShape`` for
spheres and clumps in :mod:`demcli.engine.sphere_shape`, ``PolyShape`` for convex
polyhedra in :mod:`demcli.engine.poly_shape`) sets up what differs (primitives, contact
tables, critical step, contact state groups); everything else is shared and runs
:func:`demcli.kernels.engine.run_steps`. It owns every array the kernels touch and allocates
only what the plan asks for (inactive effects get size-0 placeholders).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from demcli.engine.materials import wall_materials
from demcli.kernels import layout as K
from demcli.kernels import motion as M
from demcli.kernels.switch import static_mask
from demcli.kernels.mesh import mesh_arrays
from demcli.kernels.walls import N_WPARAMS

# adaptive damping: initial alpha (seed 002: 0.1 1/s)
ALPHA0 = 0.1


@dataclass
class Walls:
    """Rigid walls of a stage (SI). ``prm`` rows hold the W_* control parameters."""

    name: list = field(default_factory=list)
    kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int8))
    point: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    normal: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    radius: np.ndarray = field(default_factory=lambda: np.zeros(0))
    v: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    material: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    control: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int8))
    prm: np.ndarray = field(default_factory=lambda: np.zeros((0, N_WPARAMS)))
    extent: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    rigid: np.ndarray = None  # (n_w,) bool: E* and G* from the particle alone; None: none rigid
    mesh: list = None  # per wall (vertices relative to its point [m], triangles) or None; None: no mesh wall

    def __len__(self):
        return len(self.kind)

    @classmethod
    def fixed_planes(cls, points, normals, material=0):
        """Fixed plane walls (kind 0) through ``points`` [m] with ``normals`` into the domain
        (normalized here), all of ``material``; drawn over a 2 m box."""
        p = np.asarray(points, float).reshape(-1, 3)
        n = np.asarray(normals, float).reshape(-1, 3)
        n = n / np.linalg.norm(n, axis=1)[:, None]
        k = len(p)
        return cls(name=[f"w{i}" for i in range(k)], kind=np.zeros(k, np.int8), point=p, normal=n,
                   radius=np.zeros(k), v=np.zeros((k, 3)), material=np.full(k, material, np.int64),
                   control=np.zeros(k, np.int8), prm=np.zeros((k, N_WPARAMS)),
                   extent=np.tile([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0], (k, 1)))

    @classmethod
    def box_faces(cls, hi, material=0):
        """The six fixed inner faces of the box [0, hi] [m] (names x0, x1, y0, y1, z0, z1;
        normals into the box), drawn over the box."""
        lx, ly, lz = (float(c) for c in hi)
        walls = cls.fixed_planes([(0, 0, 0), (lx, 0, 0), (0, 0, 0), (0, ly, 0), (0, 0, 0), (0, 0, lz)],
                                 [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)], material)
        walls.name[:] = ["x0", "x1", "y0", "y1", "z0", "z1"]
        walls.extent[:] = [0.0, 0.0, 0.0, lx, ly, lz]
        return walls


@dataclass(frozen=True)
class Dynamics:
    """Stage-level numbers the kernel needs besides the arrays (SI)."""

    gravity: tuple = (0.0, 0.0, -9.81)
    local_damping: float = 0.0
    viscous_damping: float = 0.0
    skin: float = 0.3              # Verlet skin as a fraction of the mean sphere radius
    check_every: int = 100         # steps between guard checks
    overlap_limit: float = 0.5     # largest overlap / smaller radius before the run stops
    energy_limit: float = 1e3      # kinetic energy may not exceed this times the reference energy



def actor_loads(actors, body_of_primitive, nb):
    """(load (n_b, N_LOAD), nsmall) of the ``actors`` group (see docs/state.md).

    Actors (loading plate, sleeper) must be the last bodies, and their primitives the last
    primitives: primitives 0..nsmall-1 go through the cell grid, the actors' are paired by
    :func:`demcli.kernels.neighbors.add_actor_pairs`.
    """
    load = np.zeros((nb, M.N_LOAD))
    body = np.asarray(actors.get("body", np.zeros(0, np.int64)), np.int64)
    n_prim = len(body_of_primitive)
    if len(body) == 0:
        return load, n_prim
    first = int(body.min())
    if sorted(body.tolist()) != list(range(first, nb)):
        raise ValueError(f"actors must be the last bodies of the scene; got bodies {body.tolist()} of {nb}")
    is_actor = np.asarray(body_of_primitive) >= first
    nsmall = int(np.argmax(is_actor)) if is_actor.any() else n_prim
    if not np.all(is_actor[nsmall:]):
        raise ValueError("the actors' spheres must be the last spheres of the scene")
    for k, b in enumerate(body):
        load[b, M.L_F0:M.L_F0 + 3] = actors["load_mean"][k]
        load[b, M.L_F1:M.L_F1 + 3] = actors["load_amplitude"][k]
        load[b, M.L_OMEGA] = 2.0 * math.pi * float(actors["frequency"][k])
        load[b, M.L_PHASE] = float(actors["phase"][k])
        load[b, M.L_T0] = float(actors["start"][k])
    return load, nsmall


def is_polyhedral(groups):
    """Whether the state's bodies are convex polyhedra (a non-empty ``polyhedra`` group)."""
    return len(groups.get("polyhedra", {}).get("shape", ())) > 0


def is_clumped(groups):
    """Whether a sphere scene's bodies are clumps: more spheres than bodies, or a sphere off its
    body's centre."""
    s = groups["spheres"]
    return len(s["radius"]) != len(groups["bodies"]["mass"]) or bool(np.any(np.asarray(s["offset"]) != 0.0))


def shape_plugin(groups):
    """The shape plug-in class of a state: MixedShape (spheres and polyhedra), PolyShape or SphereShape."""
    from demcli.engine.mixed_shape import MixedShape, is_mixed
    from demcli.engine.poly_shape import PolyShape
    from demcli.engine.sphere_shape import SphereShape

    if is_mixed(groups):
        return MixedShape
    return PolyShape if is_polyhedral(groups) else SphereShape


class System:
    """Arrays and kernels of one stage, for any body shape.

    Args:
        groups: state groups ``bodies`` and the shape's (spheres: ``spheres``, optional
            ``contacts``, ``wall_contacts``, ``bonds``; polyhedra: ``polyhedra``,
            ``polyhedron_shapes``, optional ``body_contacts``, ``body_wall_contacts``), and
            optional ``actors``, ``energy``, ``adaptive_damping`` (alpha, ke_prev).
        materials: list of :class:`~demcli.engine.materials.Material`.
        model: :class:`~demcli.engine.materials.ContactModel` (polyhedra: only ``pairs``).
        plan: :class:`~demcli.engine.plan.Plan`.
        walls: :class:`Walls` (polyhedra: planes only).
        dynamics: :class:`Dynamics`; ``skin`` is a fraction of the mean primitive radius
            (spheres, or polyhedron bounding spheres).
        dt: time step [s]. time, step: clock of the input state.
        mass_scale: mass scaling for quasi-static runs: masses and inertias x factor inside
            the engine, gravity / factor (weights stay real, the critical step grows by its
            square root), ``groups()`` unscaled. A power of 2 keeps the round trip exact.
        contact_damping, adaptive_damping: switch those effects on or off without a plan
            entry (None: from the plan).
        alpha0: initial adaptive alpha [1/s] (seed 002: 0.1).
        alpha_bounds: (min, max) of alpha as multiples of alpha0 and of 1/dt:
            alpha in [alpha0 x min, max / dt]. The seed's rule is unbounded; the floor
            keeps alpha from decaying towards zero during a long quiet phase (0.99^n)
            so that it can react within tens of steps, the ceiling keeps the damping
            factor (1 - alpha dt/4)/(1 + alpha dt/4) of a half kick positive.
    """

    def __init__(self, groups, materials, model, plan, walls, dynamics, dt, time=0.0, step=0, mass_scale=1.0,
                 contact_damping=None, adaptive_damping=None, alpha0=ALPHA0, alpha_bounds=(1e-3, 1.0)):
        self.plan = plan
        self.materials = list(materials)
        self.model = model
        self.walls = walls
        self.dyn = dynamics
        self.dt = float(dt)
        self.time = float(time)
        self.step = int(step)
        flags = list(plan.flags)
        flags[K.F_DASHPOT] = plan.has("contact_damping") if contact_damping is None else bool(contact_damping)
        flags[K.F_ADAPTIVE] = plan.has("adaptive_damping") if adaptive_damping is None else bool(adaptive_damping)
        self.flags = tuple(flags)
        self.contact_damping = self.flags[K.F_DASHPOT]
        self.adaptive_damping = self.flags[K.F_ADAPTIVE]
        self.cell = None  # the periodic cell (demcli.engine.periodic_cell), set by its stage before stepping
        b = groups["bodies"]
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
        self._angmom = b.get("angmom")
        self.body_set = None if b.get("set") is None else np.asarray(b["set"], np.int64)  # generate's sets
        self._setup_walls(walls)
        self.plugin = shape_plugin(groups)(self, groups)
        n_prim = len(self.rad)
        self._actors = {k: np.asarray(val) for k, val in groups.get("actors", {}).items()}
        self.bload, self.nsmall = actor_loads(self._actors, self.plugin.body_of_primitive(self), nb)
        energy = self.flags[K.F_ENERGY]
        eg = groups.get("energy", {})
        self.esph = np.zeros((n_prim if energy else 0, 2))
        self.ebody = np.zeros(nb if energy else 0)
        self.eacc = np.zeros(1)
        self.losses0 = {k: float(np.asarray(eg.get(k, 0.0))) for k in ("damping", "friction", "body_damping",
                                                                       "wall_work")}
        self.alpha0 = float(alpha0)
        self.alpha_bounds = tuple(float(a) for a in alpha_bounds)
        self.adamp = np.zeros(M.N_ADAMP)
        ag = groups.get("adaptive_damping", {})
        self.adamp[M.A_ALPHA] = float(np.asarray(ag.get("alpha", alpha0)))
        self.adamp[M.A_KE] = float(np.asarray(ag.get("ke_prev", self.kinetic_energy())))
        self.adamp[M.A_MIN] = self.alpha0 * self.alpha_bounds[0]
        self.adamp[M.A_MAX] = math.inf
        self.counters = np.zeros(K.N_COUNTERS, np.int64)
        self.info = np.zeros(4)
        self.nl = self.plugin.initial_lists(self, groups)
        self.skin = self.dyn.skin * float(self.rad.mean()) if n_prim else 0.0
        self.max_cells = max(64, 8 * n_prim)
        self._fresh_lists = True
        self.prime = True  # evaluate F(x_0) before the first step; False when resuming from stored loads
        self.gravity = np.asarray(dynamics.gravity, np.float64) / self.mass_scale
        self.ke_limit = math.inf

    def _setup_walls(self, walls):
        """Kernel dtypes for the wall arrays (in place: the engine changes radius and prm of
        pressure-loaded and servo walls), and the arrays the step loop moves."""
        walls.kind = np.ascontiguousarray(walls.kind, np.int8)
        walls.normal = np.ascontiguousarray(walls.normal, np.float64)
        walls.radius = np.ascontiguousarray(walls.radius, np.float64)
        walls.material = np.ascontiguousarray(walls.material, np.int64)
        self.wmat = wall_materials(self.materials, walls.material, walls.rigid)
        walls.control = np.ascontiguousarray(walls.control, np.int8)
        walls.prm = np.ascontiguousarray(walls.prm, np.float64)
        self.wforce = np.zeros((len(walls), 3))
        self.wkn = np.zeros(len(walls))
        self.wpoint = np.ascontiguousarray(walls.point, np.float64).copy()
        self.wpoint0 = self.wpoint.copy()
        self.wv = np.ascontiguousarray(walls.v, np.float64).copy()
        self.wmesh = mesh_arrays(walls.mesh)  # None without mesh walls (the mesh path is not compiled)

    def angmom_from_omega(self):
        """L = R diag(I) R^T omega for each body (world frame), or the stored angular momentum."""
        if self._angmom is not None:
            return np.ascontiguousarray(self._angmom, np.float64) * self.mass_scale
        from scipy.spatial.transform import Rotation

        rot = Rotation.from_quat(self.q[:, [1, 2, 3, 0]])  # scipy: scalar last
        wb = rot.inv().apply(self.w)
        return np.ascontiguousarray(rot.apply(wb * self.inert))

    # ---- time stepping --------------------------------------------------------------
    @property
    def alpha(self):
        """Current adaptive damping coefficient alpha [1/s] (seed 002, eqs. 23-27)."""
        return float(self.adamp[M.A_ALPHA])

    @alpha.setter
    def alpha(self, value):
        self.adamp[M.A_ALPHA] = float(value)

    @property
    def rigid(self):
        """Bodies with a general inertia tensor integrate L (clumps, polyhedra)."""
        return len(self.L) == len(self.x) and len(self.x) > 0

    def critical_dt(self):
        """Critical time step of this scene [s] (the shape's estimate; see its ``critical_dt``)."""
        return self.plugin.critical_dt(self)

    @staticmethod
    def step_kernel():
        """The compiled step loop :meth:`advance` calls (numba dispatcher)."""
        from demcli.kernels.engine import run_steps

        return run_steps

    def kernel_params(self):
        """The Params tuple of the next chunk."""
        d = self.dyn
        return K.Params(self.dt, int(self.law), self.gravity, float(d.local_damping), float(d.viscous_damping),
                        float(self.skin), int(self.max_cells), int(self.nsmall), int(d.check_every),
                        float(d.overlap_limit), float(self.ke_limit))

    def kernel_bodies(self):
        """The Bodies tuple (the arrays themselves: the engine updates them in place)."""
        return K.Bodies(self.x, self.v, self.w, self.q, self.L, self.f, self.tq, self.mass, self.inert, self.bflags,
                        self.bload)

    def kernel_walls(self):
        """The WallArrays tuple (updated in place)."""
        w = self.walls
        return K.WallArrays(w.kind, self.wpoint, w.normal, w.radius, self.wv, self.wmat, w.control, w.prm,
                            self.wforce, self.wkn, self.wmesh)

    def advance(self, nsteps):
        """Run ``nsteps`` steps in compiled code; returns (status, steps done)."""
        from demcli.kernels.engine import run_steps

        self.adamp[M.A_MAX] = self.alpha_bounds[1] / self.dt if self.dt > 0 else math.inf
        bonds, bprm = self.plugin.bond_arrays(self)
        static = static_mask(self.flags)
        status, done, self.time, self.nl = run_steps(
            int(nsteps), self.time, self.flags, self.prm, self.kernel_params(), self.kernel_bodies(),
            self.plugin.geometry(self), self.plugin.members(self), self.kernel_walls(), self.nl, bonds, bprm,
            self.adamp, self.esph, self.ebody, self.eacc, self.counters, self.info, self._fresh_lists, self.step,
            self.prime, *([static] if static else []))  # none on: omitted, compiled as constants
        self._fresh_lists = False
        self.prime = False
        self.step += int(done)
        self.plugin.after_advance(self)
        return int(status), int(done)

    def set_actor_start(self, name, t0):
        """Start time [s] of the oscillating load of the actor ``name``."""
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in self._actors["name"]]
        k = names.index(name)
        self._actors["start"] = self._actors["start"].astype(np.float64)
        self._actors["start"][k] = t0
        self.bload[int(self._actors["body"][k]), M.L_T0] = t0

    # ---- measures -------------------------------------------------------------------
    def kinetic_energy(self):
        """Translational plus rotational kinetic energy [J] (fixed summation order)."""
        ke = 0.5 * float(np.sum(self.mass * np.einsum("ij,ij->i", self.v, self.v)))
        if self.rigid:
            ke += 0.5 * float(np.sum(np.einsum("ij,ij->i", self.w, self.L)))
        else:
            ke += 0.5 * float(np.sum(self.inert[:, 0] * np.einsum("ij,ij->i", self.w, self.w)))
        return ke

    def gravity_potential(self):
        """-sum m g.x [J] (zero at the origin)."""
        return -float(np.sum(self.mass * (self.x @ self.gravity))) if self.plan.has("gravity") else 0.0

    def strain_energy(self):
        """Elastic energy in contacts and bonds [J] (the shape's; polyhedra: an estimate)."""
        return self.plugin.strain_energy(self)

    def losses(self):
        """Cumulative energy [J]: contact dashpots, slip, body damping, and work done by walls."""
        d = dict(self.losses0)
        if self.flags[K.F_ENERGY]:
            d["damping"] += float(self.esph[:, 0].sum())
            d["friction"] += float(self.esph[:, 1].sum())
            d["body_damping"] += float(self.ebody.sum())
            d["wall_work"] += float(self.eacc[0])
        return d

    def energy_record(self):
        """Energy terms and the balance error E_k + E_s + E_g + losses - wall work [J]."""
        rec = {"kinetic": self.kinetic_energy(), "strain": self.strain_energy(),
               "gravity": self.gravity_potential()}
        rec.update(self.losses())
        rec["total"] = (rec["kinetic"] + rec["strain"] + rec["gravity"] + rec["damping"] + rec["friction"]
                        + rec["body_damping"] - rec["wall_work"])
        return rec

    def contact_count(self):
        """(primitive-primitive contacts, primitive-wall contacts) touching at the last evaluation."""
        return self.plugin.contact_count(self)

    def touching(self):
        """((i, j), (k, wall)): the primitive pairs touching now (bonded spheres included: each
        shape's ``touching_pairs``) and the primitive-wall pairs (``touching_walls``), as int64
        arrays; ValueError for a shape that has none (a scene of spheres with polyhedra)."""
        if not hasattr(self.plugin, "touching_pairs"):
            raise ValueError(f"the touching pairs of a {self.plugin.name} scene are not listed yet")
        return self.plugin.touching_pairs(self), self.plugin.touching_walls(self)

    # ---- snapshots ------------------------------------------------------------------
    _MUTABLE = ("x", "v", "w", "q", "L", "f", "tq", "wpoint", "wv", "wforce", "esph", "ebody", "eacc", "adamp", "nl",
                "time", "step", "bond_state", "bond_hist", "wall_radius", "wall_params")

    @property
    def wall_radius(self):
        """Cylinder radii (a pressure-loaded membrane changes its own)."""
        return self.walls.radius

    @property
    def wall_params(self):
        """Wall control rows (a pressure-loaded membrane keeps its radial rate there)."""
        return self.walls.prm

    @property
    def bond_state(self):
        return self.bonds.state

    @property
    def bond_hist(self):
        return self.bonds.hist

    def snapshot(self):
        """Copies of everything the step loop mutates (to restore the last good state)."""
        out = {}
        for k in self._MUTABLE + self.plugin.MUTABLE:
            val = getattr(self, k)
            if isinstance(val, K.Contacts):
                out[k] = K.Contacts(*(a.copy() for a in val))
            elif isinstance(val, np.ndarray):
                out[k] = val.copy()
            else:
                out[k] = val
        return out

    def restore(self, snap):
        """Back to a :meth:`snapshot`; the lists are rebuilt at the next step."""
        for k, val in snap.items():
            cur = getattr(self, k)
            if isinstance(cur, np.ndarray):
                cur[...] = val
            else:
                setattr(self, k, val)
        self._fresh_lists = True

    # ---- state exchange -------------------------------------------------------------
    def groups(self):
        """State groups of the current scene: bodies, walls, energy, actors and adaptive damping
        (when present), and the shape's groups (particles and contacts)."""
        bodies = {"x": self.x.copy(), "v": self.v.copy(), "q": self.q.copy(), "omega": self.w.copy(),
                  "mass": self.mass / self.mass_scale, "inertia": self.inert / self.mass_scale,
                  "id": self.body_id.copy(), "flags": self.bflags.copy(), "force": self.f.copy(),
                  "torque": self.tq.copy()}
        if self.rigid:
            bodies["angmom"] = self.L / self.mass_scale
        if self.body_set is not None:
            bodies["set"] = self.body_set.copy()
        w = self.walls
        walls = {"name": np.array(w.name, dtype=object), "kind": w.kind.copy(), "point": self.wpoint.copy(),
                 "normal": w.normal.copy(), "radius": w.radius.copy(), "v": self.wv.copy(),
                 "material": w.material.copy(), "control": w.control.copy(), "target": w.prm[:, 0].copy(),
                 "force": self.wforce.copy(),
                 "extent": np.asarray(w.extent) + np.tile(self.wpoint - self.wpoint0, 2)}
        out = {"bodies": bodies}
        out.update(self.plugin.groups(self))
        out["walls"] = walls
        out["energy"] = {k: np.float64(v) for k, v in self.losses().items()}
        out.update(self.plugin.late_groups(self))
        if len(self._actors):
            out["actors"] = {k: v.copy() for k, v in self._actors.items()}
        if self.adaptive_damping:
            out["adaptive_damping"] = {"alpha": np.float64(self.adamp[M.A_ALPHA]),
                                       "ke_prev": np.float64(self.adamp[M.A_KE])}
        if self.cell is not None:
            from demcli.engine.periodic_cell import groups as cell_groups

            out["cell"] = cell_groups(self.cell)
        return out

    # ---- sphere scenes (bonds, measures on spheres) -----------------------------------
    def _spheres_only(self, what):
        if self.plugin.name != "spheres":
            raise ValueError(f"{what} is for sphere and clump scenes; this scene holds {self.plugin.name}")

    def bond_touching(self, gap, fraction=1.0, rng=None, stress_free=False):
        """Bond touching sphere pairs (:meth:`demcli.engine.sphere_shape.SphereShape.bond_touching`)."""
        self._spheres_only("bonding")
        return self.plugin.bond_touching(self, gap, fraction, rng, stress_free)

    def bond_pairs(self, pi, pj, model):
        """Bond given sphere pairs (:meth:`demcli.engine.sphere_shape.SphereShape.bond_pairs`)."""
        self._spheres_only("bonding")
        return self.plugin.bond_pairs(self, pi, pj, model)

    @property
    def friction(self):
        """(n_m, n_m) view of the friction coefficients between particle materials in the pair table;
        writable: a change acts from the next step."""
        return self.prm[:, :, self.plugin.FRICTION]

    def stress(self, volume):
        """Mean stress in the particles [Pa], (3, 3), compression positive: the contact and
        bond virial over ``volume`` [m^3] (:func:`demcli.kernels.measures.contact_virial`)."""
        self._spheres_only("the contact virial")
        return self.plugin.stress(self, volume)

    def contacts_per_sphere(self):
        """(n_s,) touching sphere-sphere contacts, intact bonds and seated pairs compressed beyond
        their delta_0 of each sphere."""
        self._spheres_only("the coordination per sphere")
        return self.plugin.contacts_per_sphere(self)

    def scale_radii(self, factor):
        """Spheres-only scenes: radii x factor (scalar or per sphere), masses x factor^3 and
        inertias x factor^5 (same density); the lists are rebuilt at the next step."""
        self._spheres_only("radius scaling")
        if self.clumps:
            raise ValueError("radius scaling is for spheres-only scenes")
        f = np.broadcast_to(np.asarray(factor, np.float64), self.rad.shape)
        self.rad *= f
        self.mass *= f ** 3
        self.inert *= (f ** 5)[:, None]
        self.smass[:] = self.mass
        self._fresh_lists = True
