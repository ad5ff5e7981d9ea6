"""Bonds between spheres in memory and in the state: models, creation, carry-over, counts.

The kernels are in :mod:`demcli.kernels.bonds`. A :class:`BondSet` holds the bond list
(CSR by the first sphere, sorted by the second, with the reverse list for the gather),
each bond's model row, state (intact or the mode it broke in) and history, and the model
table. Bonds live in the state groups ``bonds`` and ``bond_models`` and carry over from
stage to stage with their history, like contacts; broken bonds stay in the list so that the
failure counts by mode survive (with zero force, except a seated pair: a broken stress-free
contact bond whose spheres have not parted, :mod:`demcli.kernels.bonds`).
"""

import math
from dataclasses import dataclass

import numpy as np

from demcli.kernels import bonds as B
from demcli.state.fields import Field, register, register_group

register_group("bond_models", "Bond models by material pair (contact, parallel and Burgers bonds)",
               writer="effect bonds")
for _name, _kind, _dims, _unit, _doc in [
        ("kind", "str", ("n_bm",), "", "contact_bond, parallel_bond or burgers"),
        ("materials", "i", ("n_bm", 2), "", "the material pair the model bonds (a <= b); (-1, -1): bonds inside "
                                             "an aggregate (INTERNAL, bonded by lattice neighbourhood, not by "
                                             "material)"),
        ("param_names", "str", ("n_bp",), "", "columns of params"),
        ("params", "f", ("n_bm", "n_bp"), "SI", "model parameters (columns B_* of demcli.kernels.bonds; inf: "
                                                 "no strength)")]:
    register(Field(f"bond_models/{_name}", _kind, _dims, _unit, _doc, writer="effect bonds"))

register_group("bonds", "Bonds between spheres with their history (broken ones kept for the counts)",
               writer="effect bonds")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("i", "i", ("n_bd",), "", "first sphere (i < j)", {"index_of": "n_s"}),
        ("j", "i", ("n_bd",), "", "second sphere", {"index_of": "n_s"}),
        ("model", "i", ("n_bd",), "", "row of bond_models", {"index_of": "n_bm"}),
        ("state", "i", ("n_bd",), "", "0 intact, 1 broken in tension, 2 broken in shear", {"dtype": "int8"}),
        ("force_n", "f", ("n_bd",), "N", "normal force on i, compression positive (Burgers: tension element "
                                         "force); 0 once broken", {}),
        ("force_s", "f", ("n_bd", 3), "N", "shear force on i (a seated broken bond: its contact's tangential "
                                           "spring)", {}),
        ("moment_t", "f", ("n_bd",), "N m", "twist moment on i about the normal (parallel bond)", {}),
        ("moment_b", "f", ("n_bd", 3), "N m", "bending moment on i (parallel bond; a seated broken bond: its "
                                             "contact's rolling moment)", {}),
        ("kelvin_n", "f", ("n_bd",), "m", "Kelvin displacement in normal tension (Burgers)", {}),
        ("kelvin_s", "f", ("n_bd", 3), "m", "Kelvin displacement in shear (Burgers)", {}),
        ("separation", "f", ("n_bd",), "m", "gap between the spheres at the last step, 0 when touching", {}),
        ("overlap0", "f", ("n_bd",), "m", "reference overlap delta_0 of a contact bond: F_n = k_n (delta - "
                                          "delta_0); the overlap at creation when installed stress-free, else 0; "
                                          "kept after it breaks (the contact law acts on delta - delta_0) until "
                                          "the spheres come apart",
         {})]:
    register(Field(f"bonds/{_name}", _kind, _dims, _unit, _doc, writer="effect bonds", **_kw))

PARAM_NAMES = ("kind", "kn", "ks", "normal_strength", "shear_strength", "bond_kn", "bond_ks", "radius_multiplier",
               "tension_km", "tension_cm", "tension_kk", "tension_ck", "shear_km", "shear_cm", "shear_kk", "shear_ck",
               "compression")
_HIST_FIELDS = (("force_n", B.H_FN, 1), ("force_s", B.H_FS, 3), ("moment_t", B.H_MT, 1), ("moment_b", B.H_MB, 3),
                ("kelvin_n", B.H_UKN, 1), ("kelvin_s", B.H_UKS, 3), ("separation", B.H_SEP, 1),
                ("overlap0", B.H_D0, 1))
_EMPTY_I = np.zeros(0, np.int64)
INTERNAL = -1
"""The material index of a model row for bonds inside an aggregate (bonded aggregates of
the 3D asphalt chain, :mod:`demcli.stages.asphalt.bonded`): no material pair selects it, so
bonding touching pairs by material never uses it."""


def model_row(kind, **params):
    """A row of the model table from named parameters (SI; strengths default to none).

    ``kind``: contact_bond (kn, ks [N/m], normal_strength, shear_strength [N]),
    parallel_bond (bond_kn, bond_ks [Pa/m], radius_multiplier, strengths [Pa]) or burgers
    (kn [N/m] in compression; tension and shear: dicts of km, kk [N/m], cm, ck [N s/m];
    strengths [N]; compression: "elastic" (default) or "burgers", the tension element then
    acting in compression too).
    """
    row = np.zeros(B.N_BPARAMS)
    row[B.B_KIND] = B.KIND_NAMES.index(kind)
    row[B.B_SN] = params.get("normal_strength", math.inf)
    row[B.B_SS] = params.get("shear_strength", math.inf)
    if kind == "contact_bond":
        row[B.B_KN], row[B.B_KS] = params["kn"], params["ks"]
    elif kind == "parallel_bond":
        row[B.B_PKN], row[B.B_PKS] = params["bond_kn"], params["bond_ks"]
        row[B.B_LAMBDA] = params.get("radius_multiplier", 1.0)
    else:
        row[B.B_KN] = params["kn"]
        for col, part in ((B.B_KMN, "tension"), (B.B_KMS, "shear")):
            el = params[part]
            row[col:col + 4] = el["km"], el["cm"], el["kk"], el["ck"]
        row[B.B_COMP] = 1.0 if params.get("compression", "elastic") == "burgers" else 0.0
    return row


@dataclass
class BondSet:
    """Bonds of a scene (arrays as the kernels take them)."""

    start: np.ndarray      # (n_s + 1,) CSR by the first sphere
    j: np.ndarray          # (n_bd,) second sphere, sorted inside each row
    model: np.ndarray      # (n_bd,) row of prm
    state: np.ndarray      # (n_bd,) int8: INTACT, BROKEN_TENSION, BROKEN_SHEAR
    hist: np.ndarray       # (n_bd, N_HIST)
    prm: np.ndarray        # (n_bm, N_BPARAMS)
    materials: np.ndarray  # (n_bm, 2) material pair of each model

    @classmethod
    def empty(cls, n_spheres):
        return cls(np.zeros(n_spheres + 1, np.int64), _EMPTY_I, _EMPTY_I, np.zeros(0, np.int8),
                   np.zeros((0, B.N_HIST)), np.zeros((0, B.N_BPARAMS)), np.zeros((0, 2), np.int64))

    @classmethod
    def from_groups(cls, groups, n_spheres):
        """The bonds a state holds (an empty set when it has none)."""
        out = cls.empty(n_spheres)
        m = groups.get("bond_models")
        if m is not None and len(np.asarray(m["params"])):
            prm = np.asarray(m["params"], np.float64)
            prm = prm.reshape(len(prm), -1)
            # a state written before the compression column: elastic compression (0)
            out.prm = np.ascontiguousarray(np.pad(prm, ((0, 0), (0, B.N_BPARAMS - prm.shape[1]))))
            out.materials = np.ascontiguousarray(m["materials"], np.int64).reshape(-1, 2)
        g = groups.get("bonds")
        if g is None or len(np.asarray(g["i"])) == 0:
            return out
        i = np.asarray(g["i"], np.int64)
        j = np.asarray(g["j"], np.int64)
        order = np.lexsort((j, i))
        hist = np.zeros((len(i), B.N_HIST))
        for name, col, width in _HIST_FIELDS:
            if name in g:  # (a state written before overlap0 existed holds loaded bonds: 0)
                hist[:, col:col + width] = np.asarray(g[name], np.float64).reshape(len(i), width)
        out.start = np.searchsorted(i[order], np.arange(n_spheres + 1)).astype(np.int64)
        out.j = np.ascontiguousarray(j[order])
        out.model = np.ascontiguousarray(np.asarray(g["model"], np.int64)[order])
        out.state = np.ascontiguousarray(np.asarray(g["state"], np.int8)[order])
        out.hist = np.ascontiguousarray(hist[order])
        return out

    def __len__(self):
        return len(self.j)

    @property
    def i(self):
        return np.repeat(np.arange(len(self.start) - 1), np.diff(self.start))

    def kernel_arrays(self):
        """(start, j, rstart, rlist, model, state, hist, bfc, btj, bed): the tuple run_steps takes."""
        from demcli.kernels.neighbors import build_reverse

        rstart, rlist = build_reverse(len(self.start) - 1, self.j)
        n = len(self.j)
        return (self.start, self.j, rstart, rlist, self.model, self.state, self.hist,
                np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 2)))

    def kernel_table(self, dt):
        """(n_bm, N_BTABLE) model table with the Burgers step coefficients for ``dt`` appended
        (zero for the other models): what the bond pass reads."""
        out = np.zeros((len(self.prm), B.N_BTABLE))
        out[:, :B.N_BPARAMS] = self.prm
        for m, p in enumerate(self.prm):
            if p[B.B_KIND] == B.BURGERS:
                for col, k in ((B.B_COEF_N, B.B_KMN), (B.B_COEF_S, B.B_KMS)):
                    out[m, col:col + 6] = B.burgers_coefficients(p[k], p[k + 1], p[k + 2], p[k + 3], float(dt))
        return out

    def groups(self):
        """State groups ``bonds`` and ``bond_models``."""
        g = {"i": self.i, "j": self.j.copy(), "model": self.model.copy(), "state": self.state.copy()}
        for name, col, width in _HIST_FIELDS:
            g[name] = self.hist[:, col].copy() if width == 1 else self.hist[:, col:col + width].copy()
        kinds = np.array([B.KIND_NAMES[int(k)] for k in self.prm[:, B.B_KIND]], dtype=object)
        models = {"kind": kinds, "materials": self.materials.copy(),
                  "param_names": np.array(PARAM_NAMES, dtype=object), "params": self.prm.copy()}
        return {"bonds": g, "bond_models": models}

    def replacing(self):
        """(n_bd,) bool: bonds that keep their pair out of the contact list (intact contact and
        Burgers bonds; broken stress-free contact bonds still seated, delta_0 > 0)."""
        kind = self.prm[self.model, B.B_KIND] if len(self.j) else np.zeros(0)
        intact = self.state == B.INTACT
        return (intact & (kind != B.PARALLEL_BOND)) | (~intact & (kind == B.CONTACT_BOND) & (self.hist[:, B.H_D0] > 0))

    def seated(self):
        """(n_bd,) bool: broken stress-free contact bonds whose pair has not come apart yet."""
        return (self.state != B.INTACT) & self.replacing()

    def counts(self):
        """{intact, broken_tension, broken_shear}."""
        return {"intact": int(np.sum(self.state == B.INTACT)),
                "broken_tension": int(np.sum(self.state == B.BROKEN_TENSION)),
                "broken_shear": int(np.sum(self.state == B.BROKEN_SHEAR))}

    def internal(self):
        """(n_bd,) bool: bonds of an INTERNAL model row (inside an aggregate)."""
        rows = self.materials[:, 0] == INTERNAL
        return rows[self.model] if len(self.j) else np.zeros(0, bool)

    def internal_counts(self):
        """{intact, broken_tension, broken_shear} of the bonds inside aggregates."""
        inside = self.internal()
        return {"intact": int(np.sum(inside & (self.state == B.INTACT))),
                "broken_tension": int(np.sum(inside & (self.state == B.BROKEN_TENSION))),
                "broken_shear": int(np.sum(inside & (self.state == B.BROKEN_SHEAR)))}

    def internal_model(self, row):
        """The model row index of the INTERNAL model ``row`` (model_row), added or replaced."""
        hit = np.flatnonzero(self.materials[:, 0] == INTERNAL)
        if len(hit):
            self.prm[hit[0]] = row
            return int(hit[0])
        self.prm = np.vstack([self.prm, row[None, :]])
        self.materials = np.vstack([self.materials, np.array([INTERNAL, INTERNAL], np.int64)[None, :]])
        return len(self.prm) - 1

    def set_models(self, materials, rows):
        """Use these models (material pairs a <= b and rows of model_row); a pair that had a
        model gets the new one, its bonds keep their history."""
        for pair, row in zip(materials, rows):
            pair = tuple(sorted(pair))
            hit = np.nonzero((self.materials[:, 0] == pair[0]) & (self.materials[:, 1] == pair[1]))[0]
            if len(hit):
                self.prm[hit[0]] = row
            else:
                self.prm = np.vstack([self.prm, row[None, :]])
                self.materials = np.vstack([self.materials, np.array(pair, np.int64)[None, :]])

    def bond_touching(self, xs, rad, smat, sbody, gap, fraction=1.0, rng=None, stress_free=False):
        """Bond every pair of spheres of different bodies whose surfaces are closer than
        ``gap`` [m] and whose material pair has a model; pairs already bonded (intact or
        broken) stay as they are. ``fraction`` < 1 bonds only that share of them, drawn
        with ``rng`` (a numpy Generator); the others stay ordinary contacts (the seed-003
        variant with frictional contacts). Returns the number of new bonds.

        ``stress_free``: a contact bond's reference overlap delta_0 is the pair's overlap
        delta = r_i + r_j - d [m] now (negative for a gap), so it holds no force where it
        is installed, F_n = k_n (delta - delta_0) (PFC's reference gap; a parallel bond is
        always installed without force, its forces being increments). Otherwise delta_0 = 0
        and the bond takes over the contact's force k_n delta (locked-in stress)."""
        from demcli.kernels.neighbors import build_pairs

        start, pi, pj = build_pairs(xs, rad, sbody, float(gap), max(64, 8 * len(rad)), None)
        d = np.linalg.norm(xs[pi] - xs[pj], axis=1)
        delta = rad[pi] + rad[pj] - d
        lookup = {tuple(p): k for k, p in enumerate(self.materials.tolist())}
        ma = np.minimum(smat[pi], smat[pj])
        mb = np.maximum(smat[pi], smat[pj])
        model = np.array([lookup.get((a, b), -1) for a, b in zip(ma.tolist(), mb.tolist())], np.int64)
        ok = (delta > -gap) & (model >= 0)
        have = set(zip(self.i.tolist(), self.j.tolist()))
        new = np.array([k for k in np.nonzero(ok)[0] if (int(pi[k]), int(pj[k])) not in have], np.int64)
        if fraction < 1.0:
            new = np.sort(rng.permutation(new)[:int(round(fraction * len(new)))])
        return self.add(pi[new], pj[new], model[new], delta[new], len(rad), stress_free)

    def add(self, pi, pj, model, delta, n_spheres, stress_free=False):
        """Append new bonds between spheres ``pi`` < ``pj`` (not yet bonded) with model rows
        ``model`` and overlaps ``delta`` [m] now (negative for a gap); ``stress_free`` as in
        :meth:`bond_touching`. Returns how many."""
        if len(pi) == 0:
            return 0
        hist = np.zeros((len(pi), B.N_HIST))
        # H_SEP: the separation, or (Burgers in compression) the elongation -delta at installation
        both = (self.prm[model, B.B_KIND] == B.BURGERS) & (self.prm[model, B.B_COMP] != 0.0)
        hist[:, B.H_SEP] = np.where(both, -delta, np.maximum(-delta, 0.0))
        if stress_free:
            cb = self.prm[model, B.B_KIND] == B.CONTACT_BOND
            hist[:, B.H_D0] = np.where(cb, delta, 0.0)
        i = np.concatenate([self.i, pi])
        j = np.concatenate([self.j, pj])
        order = np.lexsort((j, i))
        self.start = np.searchsorted(i[order], np.arange(n_spheres + 1)).astype(np.int64)
        self.j = np.ascontiguousarray(j[order])
        self.model = np.ascontiguousarray(np.concatenate([self.model, model])[order])
        self.state = np.ascontiguousarray(np.concatenate([self.state, np.zeros(len(pi), np.int8)])[order])
        self.hist = np.ascontiguousarray(np.vstack([self.hist, hist])[order])
        return len(pi)

    def critical_omega2(self, mass_min, inert_min, rad_min):
        """Largest omega^2 [1/s^2] the bonds give the lightest sphere: 2 k_n / m for the
        normal spring of a pair (m* = m / 2); 7 k_s / m for a pair's shear spring, which
        acts at the contact point and so moves both centres and turns both spheres:
        k_s (1/m_i + 1/m_j + a_i^2/I_i + a_j^2/I_j) with a = r and I = 0.4 m r^2 (the
        translational 2 k_s / m alone, or the 5 k_s / m used for contacts, is too low: a
        contact-bonded pair with k_s = k_n blew up at 0.9 x the step they give); and
        2 k_r / I for a parallel bond's bending and twisting springs (k_r = kn_b I_b,
        ks_b J_b), on the smallest sphere (bond radius lambda r_min). The shear and the
        bending modes of an equal pair are orthogonal in the mass metric, so the largest
        of the three is the pair's largest omega^2."""
        if len(self.prm) == 0:
            return 0.0
        p = self.prm
        kind = p[:, B.B_KIND]
        rb = p[:, B.B_LAMBDA] * rad_min
        area = math.pi * rb ** 2
        ib = 0.25 * area * rb ** 2
        kn = np.where(kind == B.PARALLEL_BOND, p[:, B.B_PKN] * area,
                      np.where(kind == B.BURGERS, np.maximum(p[:, B.B_KN], p[:, B.B_KMN]), p[:, B.B_KN]))
        ks = np.where(kind == B.PARALLEL_BOND, p[:, B.B_PKS] * area,
                      np.where(kind == B.BURGERS, p[:, B.B_KMS], p[:, B.B_KS]))
        kr = np.where(kind == B.PARALLEL_BOND, np.maximum(p[:, B.B_PKN] * ib, p[:, B.B_PKS] * 2 * ib), 0.0)
        w2 = np.maximum(np.maximum(2 * kn / mass_min, 7 * ks / mass_min), 2 * kr / inert_min)
        return float(w2.max())
