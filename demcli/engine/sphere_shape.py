"""The sphere shape plug-in of :class:`demcli.engine.system.System`: spheres and rigid clumps of spheres.

A spheres-only scene has sphere i = body i (the body arrays are the sphere arrays, spin
rotors); a clump scene has several member spheres per body (rigid rotors, members placed
from the body pose every step). Contact laws: linear spring-dashpot or Hertz-Mindlin
(:mod:`demcli.kernels.contact`), bonds (:mod:`demcli.engine.bonds`). State groups: ``spheres``,
``contacts`` (i, j sphere indices, force, ft, mr), ``wall_contacts`` (sphere, wall, force, ft,
mr) and the bonds' groups.
"""

import math

import numpy as np

from demcli.engine.materials import LAWS, critical_time_step, pair_table
from demcli.kernels import layout as K
from demcli.kernels.contact import P_MU

_EMPTY_I = np.empty(0, np.int64)


def _empty2(cols):
    return np.zeros((0, cols))


def stored_contacts(group, key_a, key_b, n, columns, n_b=None):
    """(CSR start, a, b, {name: rows}) of stored contacts sorted by (a, b) (the kernels'
    canonical order). ``columns``: {name: (columns or 0 for a vector, wanted)}; a wanted
    column missing from the group is zeros, an unwanted one has zero rows. ``n_b``: keep only
    contacts with b < n_b (wall contacts of walls this stage no longer has)."""
    a = np.asarray(group.get(key_a, _EMPTY_I), np.int64)
    b = np.asarray(group.get(key_b, _EMPTY_I), np.int64)
    order = np.lexsort((b, a))
    if n_b is not None:
        order = order[b[order] < n_b]
    a, b = np.ascontiguousarray(a[order]), np.ascontiguousarray(b[order])
    start = np.searchsorted(a, np.arange(n + 1)).astype(np.int64)
    rows = {}
    for name, (cols, wanted) in columns.items():
        size = len(a) if wanted else 0
        shape = (size, cols) if cols else (size,)
        rows[name] = (np.ascontiguousarray(np.asarray(group[name], np.float64)[order])
                      if wanted and name in group else np.zeros(shape))
    return start, a, b, rows


def contacts_tuple(start, ci, cj, rows, wstart, wa, ww, wrows, xref, n_walls, per_pair_torque, volumetric):
    """The engine's Contacts tuple seeded with stored contacts (touching flags on)."""
    npair = len(ci)
    nq = len(ww)
    wfc = np.zeros((nq, 5))
    wfc[:, :3] = wrows["force"]
    geo = np.zeros((npair if volumetric else 0, 3))
    wgeo = np.zeros((nq if volumetric else 0, 3))
    if volumetric:
        geo[:, 0] = rows["depth"]
        wgeo[:, 0] = wrows["depth"]
    return K.Contacts(start, ci, cj, np.zeros(len(start), np.int64), _EMPTY_I, rows["ft"], rows["mr"],
                      rows["force"], np.zeros((npair if per_pair_torque else 0, 3)), np.ones(npair, np.uint8),
                      _empty2(2), geo, np.zeros(npair if volumetric else 0, np.int32),
                      np.zeros((npair if volumetric else 0, 3)), np.zeros(npair if volumetric else 0),
                      rows.get("box", np.zeros((0, 6))), wstart, wa, ww, wrows["ft"], wrows["mr"], wfc,
                      np.zeros((nq, 3)), np.zeros((0, 2)), wgeo, xref, np.zeros((n_walls, 3)))


class SphereShape:
    """Spheres and clumps: sets the system's sphere arrays and gives the engine their tuples."""

    name = "spheres"
    MUTABLE = ("xs", "vs", "ws", "fs", "ts")  # what the step loop changes besides the System's arrays
    FRICTION = P_MU  # column of prm with the friction coefficient

    def __init__(self, s, groups):
        from demcli.engine.bonds import BondSet

        s.law = LAWS[s.model.law]
        s.prm = pair_table(s.materials, s.model)
        sp = groups["spheres"]
        nb = len(s.mass)
        s.clumps = s.flags[K.F_CLUMPS]
        s.sbody = np.ascontiguousarray(sp["body"], np.int64)
        s.soff = np.ascontiguousarray(sp["offset"], np.float64)
        s.rad = np.ascontiguousarray(sp["radius"], np.float64).copy()
        s.smat = np.ascontiguousarray(sp["material"], np.int64)
        ns = len(s.rad)
        if s.clumps:
            s.L = s.angmom_from_omega()
            s.xs, s.vs, s.ws, s.fs, s.ts = (np.zeros((ns, 3)) for _ in range(5))
            order = np.argsort(s.sbody, kind="stable")
            s.mstart = np.searchsorted(s.sbody[order], np.arange(nb + 1)).astype(np.int64)
            s.mlist = order.astype(np.int64)
            self._place_members(s)
        else:
            if ns != nb or not np.array_equal(s.sbody, np.arange(nb)):
                raise ValueError("a spheres-only scene needs sphere i to be body i")
            s.L = _empty2(3)
            s.xs, s.vs, s.ws, s.fs, s.ts = s.x, s.v, s.w, s.f, s.tq
            s.mstart = np.zeros(1, np.int64)
            s.mlist = _EMPTY_I
        s.smass = np.ascontiguousarray(s.mass[s.sbody])
        s.bonds = BondSet.from_groups(groups, ns) if s.plan.has("bonds") else BondSet.empty(ns)
        s._bond_arrays = s.bonds.kernel_arrays()
        self._replacing = None

    @staticmethod
    def _place_members(s):
        from scipy.spatial.transform import Rotation

        rot = Rotation.from_quat(s.q[:, [1, 2, 3, 0]])
        off = rot[s.sbody].apply(s.soff) if len(s.sbody) else np.zeros((0, 3))
        s.xs[:] = s.x[s.sbody] + off
        s.vs[:] = s.v[s.sbody] + np.cross(s.w[s.sbody], off)
        s.ws[:] = s.w[s.sbody]

    @staticmethod
    def body_of_primitive(s):
        return s.sbody

    # ---- the engine's tuples ----------------------------------------------------------
    @staticmethod
    def geometry(s):
        from demcli.kernels.shapes.spheres import SphereGeometry

        return SphereGeometry(s.xs, s.vs, s.ws, s.rad, s.smat, s.smass, s.sbody, s.soff, s.cell)

    @staticmethod
    def members(s):
        """Members of clumps; None for single spheres (the engine compiles no member pass)."""
        return K.Members(s.mstart, s.mlist, s.xs, s.fs, s.ts) if s.clumps else None

    def bond_arrays(self, s):
        """(bond state tuple, bond-model table for the current dt) (cached on dt). The tuple is
        passed (empty) without the bonds effect too, the pass switched by the flag: one compiled
        sphere engine serves every stage of a case (an asphalt case bonds in its later stages),
        and the test suite compiles one sphere variant, not two."""
        self._replacing = s.bonds.replacing()
        key = (s.dt, s.bonds.prm.tobytes())
        if getattr(self, "_bond_table_key", None) != key:
            self._bond_table_key = key
            self._bond_table = s.bonds.kernel_table(s.dt)
        return s._bond_arrays, self._bond_table

    def after_advance(self, s):
        if len(s.bonds) and not np.array_equal(self._replacing, s.bonds.replacing()):
            s._fresh_lists = True  # a bond broke or a seated pair came apart: it joins the contact list

    @staticmethod
    def initial_lists(s, groups):
        """Contacts seeded with the stored contacts: their history for carry-over, and their
        forces and touching flags, so that :meth:`groups` of a system not yet stepped gives back
        the stored contacts (a stage resumed from a checkpoint of its last step)."""
        ns = len(s.rad)
        cols = {"ft": (3, s.flags[K.F_FRICTION]), "mr": (3, s.flags[K.F_ROLLING]), "force": (3, True)}
        start, ci, cj, rows = stored_contacts(groups.get("contacts", {}), "i", "j", ns, cols)
        wstart, wsph, ww, wrows = stored_contacts(groups.get("wall_contacts", {}), "sphere", "wall", ns, cols,
                                                  len(s.walls))
        return contacts_tuple(start, ci, cj, rows, wstart, wsph, ww, wrows, s.xs.copy(), len(s.walls), False, False)

    # ---- measures -----------------------------------------------------------------------
    @staticmethod
    def critical_dt(s):
        """:func:`critical_time_step` of the contacts, lowered by the bonds (their omega^2 added to
        the contacts', a bond and a contact acting side by side; :meth:`BondSet.critical_omega2`)."""
        dt = critical_time_step(s.model, s.prm, s.materials, s.mass, s.rad, s.sbody, s.smat)
        if s.model.law != "linear":  # the Rayleigh step follows the density, scaled with the masses
            dt *= math.sqrt(s.mass_scale)
        if not len(s.bonds.prm) or not len(s.rad):
            return dt
        w2 = s.bonds.critical_omega2(float(s.smass.min()), float(s.inert.min()), float(s.rad.min()))
        return 2.0 / math.sqrt((2.0 / dt) ** 2 + w2) if w2 > 0 else dt

    @staticmethod
    def strain_energy(s):
        """Elastic energy in contacts and bonds [J]."""
        from demcli.kernels.bonds import bond_strain_energy
        from demcli.kernels.shapes.spheres import total_strain_energy

        nl = s.nl
        w = s.walls
        bd = s.bonds
        friction, rolling = s.flags[K.F_FRICTION], s.flags[K.F_ROLLING]
        eb = float(bond_strain_energy(bd.start, bd.j, bd.model, bd.state, bd.hist, bd.prm, s.xs, s.rad, s.smat,
                                      s.prm, s.law, friction, rolling)) if len(bd) else 0.0
        return eb + float(total_strain_energy(nl.pi, nl.pj, s.xs, s.rad, s.smat, s.prm, s.law, nl.ft, nl.mr,
                                              friction, rolling, nl.wstart, nl.wwall, w.kind, s.wpoint, w.normal,
                                              w.radius, s.wmat, nl.wft, nl.wmr, s.wmesh, s.cell))

    @staticmethod
    def contact_count(s):
        """(sphere-sphere contacts, sphere-wall contacts) touching now."""
        nl = s.nl
        n_pw = int(np.count_nonzero(np.any(nl.wfc[:, :3] != 0.0, axis=1))) if len(nl.wfc) else 0
        return int(nl.act.sum()), n_pw

    @staticmethod
    def stress(s, volume):
        from demcli.kernels.measures import contact_virial

        nl = s.nl
        w = s.walls
        ba = s._bond_arrays
        return contact_virial(nl.pi, nl.pj, nl.act, nl.fc, s.xs, s.rad, nl.wstart, nl.wwall, nl.wfc, w.kind, s.wpoint,
                              w.normal, w.radius, s.wmesh, ba[0], ba[1], ba[7]) / volume

    @staticmethod
    def contacts_per_sphere(s):
        i, j = SphereShape.touching_pairs(s)
        n = len(s.rad)
        return np.bincount(i, minlength=n) + np.bincount(j, minlength=n)

    @staticmethod
    def touching_pairs(s):
        """(i, j) sphere indices of the pairs touching now: touching contacts, then intact bonds
        and seated pairs compressed beyond their delta_0 (a pair a bond replaces is no contact)."""
        nl = s.nl
        act = nl.act.astype(bool)
        i, j = nl.pi[act], nl.pj[act]
        bd = s.bonds
        if len(bd):
            from demcli.kernels import bonds as B

            bi, bj = bd.i, bd.j
            delta = s.rad[bi] + s.rad[bj] - np.linalg.norm(s.xs[bi] - s.xs[bj], axis=1)
            ok = (bd.state == B.INTACT) | (bd.seated() & (delta > bd.hist[:, B.H_D0]))
            i, j = np.concatenate([i, bi[ok]]), np.concatenate([j, bj[ok]])
        return np.asarray(i, np.int64), np.asarray(j, np.int64)

    @staticmethod
    def touching_walls(s):
        """(sphere, wall) of the sphere-wall contacts touching now."""
        nl = s.nl
        wact = np.any(nl.wfc[:, :3] != 0.0, axis=1) if len(nl.wfc) else np.zeros(0, bool)
        return np.asarray(nl.wprim[wact], np.int64), np.asarray(nl.wwall[wact], np.int64)

    @staticmethod
    def bond_touching(s, gap, fraction, rng, stress_free):
        """Bond every touching pair whose material pair has a bond model (surfaces closer than
        ``gap`` [m]), or a random ``fraction`` of them drawn with ``rng``; returns the number of
        new bonds. The pair list is rebuilt. ``stress_free``: contact bonds hold no force at their
        installed overlap (:meth:`BondSet.bond_touching`)."""
        if not s.plan.has("bonds"):
            raise ValueError("bonds are not an effect of this stage")
        n = s.bonds.bond_touching(s.xs, s.rad, s.smat, s.sbody, gap, fraction, rng, stress_free)
        SphereShape._bonds_changed(s)
        return n

    @staticmethod
    def bond_pairs(s, pi, pj, model):
        """Bond the sphere pairs ``pi`` < ``pj`` (not yet bonded) with the model row ``model``,
        installed at their overlap now; returns the number of new bonds."""
        if not s.plan.has("bonds"):
            raise ValueError("bonds are not an effect of this stage")
        delta = s.rad[pi] + s.rad[pj] - np.linalg.norm(s.xs[pi] - s.xs[pj], axis=1)
        n = s.bonds.add(pi, pj, np.full(len(pi), model, np.int64), delta, len(s.rad))
        SphereShape._bonds_changed(s)
        return n

    @staticmethod
    def _bonds_changed(s):
        """After new bonds: the kernels' bond arrays, fresh lists, and the contacts a bond now
        replaces taken out of the contact list."""
        s._bond_arrays = s.bonds.kernel_arrays()
        s._fresh_lists = True
        # contacts a bond now replaces are no longer contacts (the rebuilt list leaves them out)
        bd = s.bonds
        replaces = bd.replacing()
        bonded = set(zip(bd.i[replaces].tolist(), bd.j[replaces].tolist()))
        nl = s.nl
        for c in np.nonzero(nl.act)[0]:
            if (int(nl.pi[c]), int(nl.pj[c])) in bonded:
                nl.act[c] = 0

    # ---- state exchange -------------------------------------------------------------------
    @staticmethod
    def groups(s):
        """spheres, contacts (touching pairs: i, j, force on i, ft, mr), wall_contacts (sphere,
        wall, force on the sphere, ft, mr) and the bonds' groups."""
        nl = s.nl
        friction, rolling = s.flags[K.F_FRICTION], s.flags[K.F_ROLLING]
        act = nl.act.astype(bool)
        contacts = {"i": nl.pi[act].copy(), "j": nl.pj[act].copy(), "force": nl.fc[act].copy()}
        if friction:
            contacts["ft"] = nl.ft[act].copy()
        if rolling:
            contacts["mr"] = nl.mr[act].copy()
        wact = np.any(nl.wfc[:, :3] != 0.0, axis=1) if len(nl.wfc) else np.zeros(0, bool)
        wall_contacts = {"sphere": nl.wprim[wact].copy(), "wall": nl.wwall[wact].copy(),
                         "force": nl.wfc[wact, :3].copy()}
        if friction:
            wall_contacts["ft"] = nl.wft[wact].copy()
        if rolling:
            wall_contacts["mr"] = nl.wmr[wact].copy()
        spheres = {"body": s.sbody.copy(), "offset": s.soff.copy(), "radius": s.rad.copy(),
                   "material": s.smat.copy()}
        return {"spheres": spheres, "contacts": contacts, "wall_contacts": wall_contacts}

    @staticmethod
    def late_groups(s):
        """The bonds' groups (written after walls and energy)."""
        return s.bonds.groups() if s.plan.has("bonds") else {}
