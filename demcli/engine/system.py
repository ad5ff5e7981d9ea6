"""A scene in memory: structure-of-arrays state, plan, and the compiled step loop.

:class:`System` is built from a state's groups (see docs/state.md), a stage's contact
model, effects and walls. It owns every array the kernels touch and allocates only
what the plan asks for (inactive effects get size-0 placeholders).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from demcli.engine.materials import LAWS, critical_time_step, pair_table
from demcli.kernels import layout as K
from demcli.kernels.walls import N_WPARAMS

_EMPTY_I = np.empty(0, np.int64)


def _empty2(cols):
    return np.zeros((0, cols))


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


class BodySystem:
    """What every engine (spheres and clumps, polyhedra) shares: energy measures and snapshots.

    Subclasses provide the arrays (x, v, w, L, mass, inert, ...), ``plan``, ``gravity``, the
    loss accumulators (losses0, esph, ebody, eacc), ``strain_energy()`` and ``_MUTABLE``:
    the attributes the step loop changes.
    """

    _MUTABLE = ()

    @property
    def rotation_from_angmom(self):
        """Bodies with a general inertia tensor: rotational energy omega.L / 2."""
        return self.clumps

    def _angmom_from_omega(self):
        """L = R diag(I) R^T omega for each body (world frame)."""
        from scipy.spatial.transform import Rotation

        rot = Rotation.from_quat(self.q[:, [1, 2, 3, 0]])  # scipy: scalar last
        wb = rot.inv().apply(self.w)
        return np.ascontiguousarray(rot.apply(wb * self.inert))

    def kinetic_energy(self):
        """Translational plus rotational kinetic energy [J] (fixed summation order)."""
        ke = 0.5 * float(np.sum(self.mass * np.einsum("ij,ij->i", self.v, self.v)))
        if self.rotation_from_angmom:
            ke += 0.5 * float(np.sum(np.einsum("ij,ij->i", self.w, self.L)))
        else:
            ke += 0.5 * float(np.sum(self.inert[:, 0] * np.einsum("ij,ij->i", self.w, self.w)))
        return ke

    def gravity_potential(self):
        """-sum m g.x [J] (zero at the origin)."""
        return -float(np.sum(self.mass * (self.x @ self.gravity))) if self.plan.has("gravity") else 0.0

    def losses(self):
        """Cumulative energy [J]: contact dashpots, slip, body damping, and work done by walls."""
        d = dict(self.losses0)
        if self.plan.has("energy"):
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

    def snapshot(self):
        """Copies of everything the step loop mutates (to restore the last good state)."""
        return {k: (tuple(a.copy() for a in getattr(self, k)) if k == "nl" else
                    getattr(self, k).copy() if isinstance(getattr(self, k), np.ndarray) else getattr(self, k))
                for k in self._MUTABLE}

    def restore(self, snap):
        for k, val in snap.items():
            cur = getattr(self, k)
            if isinstance(cur, np.ndarray):
                cur[...] = val
            else:
                setattr(self, k, val)
        self._fresh_lists = True


class System(BodySystem):
    """Arrays and kernels of one stage.

    Args:
        groups: state groups ``bodies``, ``spheres`` and optional ``contacts``,
            ``wall_contacts``, ``energy``.
        materials: list of :class:`~demcli.engine.materials.Material`.
        model: :class:`~demcli.engine.materials.ContactModel`.
        plan: :class:`~demcli.engine.plan.Plan`.
        walls: :class:`Walls`.
        dynamics: :class:`Dynamics`.
        dt: time step [s].
        time, step: clock of the input state.
        mass_scale: mass scaling for quasi-static runs (as for polyhedra): masses and
            inertias x factor inside the engine, gravity / factor, ``groups()`` unscaled.
    """

    def __init__(self, groups, materials, model, plan, walls, dynamics, dt, time=0.0, step=0, mass_scale=1.0):
        from demcli.engine.bonds import BondSet

        self.plan = plan
        self.materials = list(materials)
        self.model = model
        self.walls = walls
        self.dyn = dynamics
        self.dt = float(dt)
        self.time = float(time)
        self.step = int(step)
        self.law = LAWS[model.law]
        self.flags = plan.flags
        self.prm = pair_table(self.materials, model)
        b = groups["bodies"]
        s = groups["spheres"]
        self.body_id = np.ascontiguousarray(b["id"], np.int64)
        self.x = np.ascontiguousarray(b["x"], np.float64).copy()
        self.v = np.ascontiguousarray(b["v"], np.float64).copy()
        self.w = np.ascontiguousarray(b["omega"], np.float64).copy()
        self.q = np.ascontiguousarray(b["q"], np.float64).copy()
        self.mass_scale = float(mass_scale)
        self.mass = np.ascontiguousarray(b["mass"], np.float64) * self.mass_scale
        self.inert = np.ascontiguousarray(b["inertia"], np.float64) * self.mass_scale
        self.bflags = np.ascontiguousarray(b["flags"], np.int8)
        nb = len(self.mass)
        self.f = np.ascontiguousarray(b.get("force", np.zeros((nb, 3))), np.float64).copy()
        self.tq = np.ascontiguousarray(b.get("torque", np.zeros((nb, 3))), np.float64).copy()
        self.clumps = self.flags[K.F_CLUMPS]
        self.sbody = np.ascontiguousarray(s["body"], np.int64)
        self.soff = np.ascontiguousarray(s["offset"], np.float64)
        self.rad = np.ascontiguousarray(s["radius"], np.float64).copy()
        self.smat = np.ascontiguousarray(s["material"], np.int64)
        ns = len(self.rad)
        if self.clumps:
            self.L = np.ascontiguousarray(b["angmom"], np.float64) * self.mass_scale if "angmom" in b \
                else self._angmom_from_omega()
            self.xs = np.zeros((ns, 3))
            self.vs = np.zeros((ns, 3))
            self.ws = np.zeros((ns, 3))
            self.fs = np.zeros((ns, 3))
            self.ts = np.zeros((ns, 3))
            order = np.argsort(self.sbody, kind="stable")
            self.mstart = np.searchsorted(self.sbody[order], np.arange(nb + 1)).astype(np.int64)
            self.mlist = order.astype(np.int64)
            self._place_members()
        else:
            if ns != nb or not np.array_equal(self.sbody, np.arange(nb)):
                raise ValueError("a spheres-only scene needs sphere i to be body i")
            self.L = _empty2(3)
            self.xs, self.vs, self.ws, self.fs, self.ts = self.x, self.v, self.w, self.f, self.tq
            self.mstart = np.zeros(1, np.int64)
            self.mlist = _EMPTY_I
        self.smass = np.ascontiguousarray(self.mass[self.sbody])
        self.wforce = np.zeros((len(walls), 3))
        self.wkn = np.zeros(len(walls))
        self.wpoint = np.ascontiguousarray(walls.point, np.float64).copy()
        self.wpoint0 = self.wpoint.copy()
        self.wv = np.ascontiguousarray(walls.v, np.float64).copy()
        energy = plan.has("energy")
        eg = groups.get("energy", {})
        self.esph = np.zeros((ns if energy else 0, 2))
        self.ebody = np.zeros(nb if energy else 0)
        self.eacc = np.zeros(1)
        self.losses0 = {k: float(np.asarray(eg.get(k, 0.0))) for k in ("damping", "friction", "body_damping", "wall_work")}
        self.counters = np.zeros(K.N_COUNTERS, np.int64)
        self.info = np.zeros(4)
        self.nl = self._initial_lists(groups)
        self.skin = self.dyn.skin * float(self.rad.mean()) if ns else 0.0
        self.max_cells = max(64, 8 * ns)
        self._fresh_lists = True
        self.prime = True  # evaluate F(x_0) before the first step; False when resuming from stored loads
        self.gravity = np.asarray(dynamics.gravity, np.float64) / self.mass_scale
        self.ke_limit = math.inf
        self.bonds = BondSet.from_groups(groups, ns) if plan.has("bonds") else BondSet.empty(ns)
        self._bond_arrays = self.bonds.kernel_arrays()

    # ---- bonds ------------------------------------------------------------------------
    def bond_touching(self, gap, fraction=1.0, rng=None, stress_free=False):
        """Bond every touching pair whose material pair has a bond model (surfaces closer
        than ``gap`` [m]), or a random ``fraction`` of them drawn with ``rng``; returns the
        number of new bonds. The pair list is rebuilt. ``stress_free``: contact bonds hold
        no force at their installed overlap (:meth:`BondSet.bond_touching`)."""
        if not self.plan.has("bonds"):
            raise ValueError("bonds are not an effect of this stage")
        n = self.bonds.bond_touching(self.xs, self.rad, self.smat, self.sbody, gap, fraction, rng, stress_free)
        self._bond_arrays = self.bonds.kernel_arrays()
        self._fresh_lists = True
        # contacts a bond now replaces are no longer contacts (the rebuilt list leaves them out)
        bd = self.bonds
        replaces = bd.replacing()
        bonded = set(zip(bd.i[replaces].tolist(), bd.j[replaces].tolist()))
        nl = self.nl
        for c in np.nonzero(nl[K.NL_ACT])[0]:
            if (int(nl[K.NL_PI][c]), int(nl[K.NL_PJ][c])) in bonded:
                nl[K.NL_ACT][c] = 0
        return n

    def _bond_table(self):
        """The bond models with their Burgers step coefficients for the current dt (cached)."""
        key = (self.dt, self.bonds.prm.tobytes())
        if getattr(self, "_bond_table_key", None) != key:
            self._bond_table_key = key
            self._bond_table_cache = self.bonds.kernel_table(self.dt)
        return self._bond_table_cache

    @property
    def bond_state(self):
        return self.bonds.state

    @property
    def bond_hist(self):
        return self.bonds.hist

    # ---- set-up helpers -------------------------------------------------------------
    def _place_members(self):
        from scipy.spatial.transform import Rotation

        rot = Rotation.from_quat(self.q[:, [1, 2, 3, 0]])
        off = rot[self.sbody].apply(self.soff) if len(self.sbody) else np.zeros((0, 3))
        self.xs[:] = self.x[self.sbody] + off
        self.vs[:] = self.v[self.sbody] + np.cross(self.w[self.sbody], off)
        self.ws[:] = self.w[self.sbody]

    def _initial_lists(self, groups):
        """Neighbour state seeded with the stored contacts: their history for carry-over, and
        their forces and touching flags, so that :meth:`groups` of a system not yet stepped
        gives back the stored contacts (a stage resumed from a checkpoint of its last step)."""
        ns = len(self.rad)
        start, ci, cj, ft, mr, fc = self._stored_history(groups.get("contacts", {}), "i", "j", ns)
        wstart, ws_, ww, wft, wmr, wf = self._stored_history(groups.get("wall_contacts", {}), "sphere", "wall", ns)
        wfc = np.zeros((len(ww), 5))
        wfc[:, :3] = wf
        return (start, ci, cj, np.zeros(ns + 1, np.int64), _EMPTY_I,
                ft, mr, fc, _empty2(3), np.ones(len(ci), np.uint8), _empty2(2),
                wstart, ws_, ww, wft, wmr, wfc,
                self.xs.copy(), np.zeros((len(self.walls), 3)))

    def _stored_history(self, group, key_a, key_b, ns):
        """(CSR start, a, b, ft, mr, force) of stored contacts sorted by (a, b) (the kernels'
        canonical order); history rows only for the active effects."""
        a = np.asarray(group.get(key_a, _EMPTY_I), np.int64)
        b = np.asarray(group.get(key_b, _EMPTY_I), np.int64)
        order = np.lexsort((b, a))
        a, b = np.ascontiguousarray(a[order]), np.ascontiguousarray(b[order])
        start = np.searchsorted(a, np.arange(ns + 1)).astype(np.int64)
        force = np.zeros((len(a), 3))
        if "force" in group:
            force[:] = np.asarray(group["force"], np.float64)[order]
        hist = []
        for name, flag in (("ft", K.F_FRICTION), ("mr", K.F_ROLLING)):
            if not self.flags[flag]:
                hist.append(_empty2(3))
            elif name in group:
                hist.append(np.ascontiguousarray(group[name][order], np.float64))
            else:
                hist.append(np.zeros((len(a), 3)))
        return start, a, b, hist[0], hist[1], force

    # ---- time stepping --------------------------------------------------------------
    def critical_dt(self):
        """Critical time step of this scene [s]: :func:`critical_time_step` of the contacts,
        lowered by the bonds (their omega^2 added to the contacts', a bond and a contact
        acting side by side; :meth:`BondSet.critical_omega2`)."""
        dt = critical_time_step(self.model, self.prm, self.materials, self.mass, self.rad, self.sbody, self.smat)
        if self.model.law != "linear":  # the Rayleigh step follows the density, scaled with the masses
            dt *= math.sqrt(self.mass_scale)
        if not len(self.bonds.prm) or not len(self.rad):
            return dt
        w2 = self.bonds.critical_omega2(float(self.smass.min()), float(self.inert.min()), float(self.rad.min()))
        return 2.0 / math.sqrt((2.0 / dt) ** 2 + w2) if w2 > 0 else dt

    @staticmethod
    def step_kernel():
        """The compiled step loop :meth:`advance` calls (numba dispatcher)."""
        from demcli.kernels.step import run_steps

        return run_steps

    def advance(self, nsteps):
        """Run ``nsteps`` steps in compiled code; returns (status, steps done)."""
        from demcli.kernels.step import run_steps

        w = self.walls
        replacing = self.bonds.replacing()
        status, done, self.time, self.nl = run_steps(
            int(nsteps), self.time, self.dt, self.law, self.flags, self.prm, self.gravity,
            float(self.dyn.local_damping), float(self.dyn.viscous_damping),
            (self.x, self.v, self.w, self.q, self.L, self.f, self.tq), self.mass, self.inert, self.bflags,
            (self.xs, self.vs, self.ws, self.fs, self.ts), self.rad, self.smat, self.smass, self.sbody,
            self.soff, self.mstart, self.mlist,
            w.kind, self.wpoint, w.normal, w.radius, self.wv, w.material, w.control, w.prm,
            self.wforce, self.wkn,
            self.nl, self.skin, self.max_cells,
            self.esph, self.ebody, self.eacc, self._bond_arrays, self._bond_table(),
            int(self.dyn.check_every), float(self.dyn.overlap_limit), float(self.ke_limit),
            self.counters, self.info, self._fresh_lists, self.step, self.prime)
        self._fresh_lists = False
        self.prime = False
        self.step += int(done)
        if len(self.bonds) and not np.array_equal(replacing, self.bonds.replacing()):
            self._fresh_lists = True  # a bond broke or a seated pair came apart: it joins the contact list
        return int(status), int(done)

    # ---- measures -------------------------------------------------------------------
    _MUTABLE = ("x", "v", "w", "q", "L", "f", "tq", "xs", "vs", "ws", "fs", "ts", "wpoint", "wv", "wforce", "esph",
                "ebody", "eacc", "nl", "time", "step", "bond_state", "bond_hist", "wall_radius", "wall_params")

    @property
    def wall_radius(self):
        """Cylinder radii (a pressure-loaded membrane changes its own)."""
        return self.walls.radius

    @property
    def wall_params(self):
        """Wall control rows (a pressure-loaded membrane keeps its radial rate there)."""
        return self.walls.prm

    def strain_energy(self):
        """Elastic energy in contacts and bonds [J]."""
        from demcli.kernels.bonds import bond_strain_energy
        from demcli.kernels.step import total_strain_energy

        nl = self.nl
        w = self.walls
        bd = self.bonds
        eb = float(bond_strain_energy(bd.start, bd.j, bd.model, bd.state, bd.hist, bd.prm, self.xs, self.rad,
                                      self.smat, self.prm, self.law, self.flags[K.F_FRICTION],
                                      self.flags[K.F_ROLLING])) if len(bd) else 0.0
        return eb + float(total_strain_energy(
            nl[K.NL_PI], nl[K.NL_PJ], self.xs, self.rad, self.smat, self.prm, self.law, nl[K.NL_FT], nl[K.NL_MR],
            self.flags[K.F_FRICTION], self.flags[K.F_ROLLING], nl[K.NL_WSTART], nl[K.NL_WWALL], w.kind, self.wpoint,
            w.normal, w.radius, w.material, nl[K.NL_WFT], nl[K.NL_WMR]))

    def stress(self, volume):
        """Mean stress in the particles [Pa], (3, 3), compression positive: the contact and
        bond virial over ``volume`` [m^3] (:func:`demcli.kernels.measures.contact_virial`)."""
        from demcli.kernels.measures import contact_virial

        nl = self.nl
        w = self.walls
        ba = self._bond_arrays
        return contact_virial(nl[K.NL_PI], nl[K.NL_PJ], nl[K.NL_ACT], nl[K.NL_FC], self.xs, nl[K.NL_WSTART],
                              nl[K.NL_WWALL], nl[K.NL_WFC], w.kind, self.wpoint, w.normal, w.radius,
                              ba[0], ba[1], ba[7]) / volume

    def contacts_per_sphere(self):
        """(n_s,) touching sphere-sphere contacts, intact bonds and seated pairs compressed beyond
        their delta_0 of each sphere."""
        nl = self.nl
        act = nl[K.NL_ACT].astype(bool)
        n = len(self.rad)
        z = np.bincount(nl[K.NL_PI][act], minlength=n) + np.bincount(nl[K.NL_PJ][act], minlength=n)
        bd = self.bonds
        if len(bd):
            from demcli.kernels import bonds as B

            i, j = bd.i, bd.j
            delta = self.rad[i] + self.rad[j] - np.linalg.norm(self.xs[i] - self.xs[j], axis=1)
            ok = (bd.state == B.INTACT) | (bd.seated() & (delta > bd.hist[:, B.H_D0]))
            z = z + np.bincount(i[ok], minlength=n) + np.bincount(j[ok], minlength=n)
        return z

    def scale_radii(self, factor):
        """Spheres-only scenes: radii x factor (scalar or per sphere), masses x factor^3 and
        inertias x factor^5 (same density); the lists are rebuilt at the next step."""
        if self.clumps:
            raise ValueError("radius scaling is for spheres-only scenes")
        f = np.broadcast_to(np.asarray(factor, np.float64), self.rad.shape)
        self.rad *= f
        self.mass *= f ** 3
        self.inert *= (f ** 5)[:, None]
        self.smass[:] = self.mass
        self._fresh_lists = True

    def contact_count(self):
        """(sphere-sphere contacts, sphere-wall contacts) touching now."""
        nl = self.nl
        n_pp = int(nl[K.NL_ACT].sum())
        wfc = nl[K.NL_WFC]
        n_pw = int(np.count_nonzero(np.any(wfc[:, :3] != 0.0, axis=1))) if len(wfc) else 0
        return n_pp, n_pw

    # ---- state exchange -------------------------------------------------------------
    def groups(self):
        """State groups of the current scene (bodies, spheres, contacts, walls, energy)."""
        nl = self.nl
        act = nl[K.NL_ACT].astype(bool)
        contacts = {"i": nl[K.NL_PI][act].copy(), "j": nl[K.NL_PJ][act].copy(), "force": nl[K.NL_FC][act].copy()}
        if self.flags[K.F_FRICTION]:
            contacts["ft"] = nl[K.NL_FT][act].copy()
        if self.flags[K.F_ROLLING]:
            contacts["mr"] = nl[K.NL_MR][act].copy()
        wfc = nl[K.NL_WFC]
        wact = np.any(wfc[:, :3] != 0.0, axis=1) if len(wfc) else np.zeros(0, bool)
        wall_contacts = {"sphere": nl[K.NL_WSPH][wact].copy(), "wall": nl[K.NL_WWALL][wact].copy(), "force": wfc[wact, :3].copy()}
        if self.flags[K.F_FRICTION]:
            wall_contacts["ft"] = nl[K.NL_WFT][wact].copy()
        if self.flags[K.F_ROLLING]:
            wall_contacts["mr"] = nl[K.NL_WMR][wact].copy()
        bodies = {"x": self.x.copy(), "v": self.v.copy(), "q": self.q.copy(), "omega": self.w.copy(),
                  "mass": self.mass / self.mass_scale, "inertia": self.inert / self.mass_scale,
                  "id": self.body_id.copy(), "flags": self.bflags.copy(), "force": self.f.copy(),
                  "torque": self.tq.copy()}
        if self.clumps:
            bodies["angmom"] = self.L / self.mass_scale
        spheres = {"body": self.sbody.copy(), "offset": self.soff.copy(), "radius": self.rad.copy(),
                   "material": self.smat.copy()}
        w = self.walls
        walls = {"name": np.array(w.name, dtype=object), "kind": w.kind.copy(), "point": self.wpoint.copy(),
                 "normal": w.normal.copy(), "radius": w.radius.copy(), "v": self.wv.copy(),
                 "material": w.material.copy(), "control": w.control.copy(), "target": w.prm[:, 0].copy(),
                 "force": self.wforce.copy(),
                 "extent": w.extent + np.tile(self.wpoint - self.wpoint0, 2)}
        energy = {k: np.float64(v) for k, v in self.losses().items()}
        out = {"bodies": bodies, "spheres": spheres, "contacts": contacts, "wall_contacts": wall_contacts,
               "walls": walls, "energy": energy}
        if self.plan.has("bonds"):
            out.update(self.bonds.groups())
        return out
