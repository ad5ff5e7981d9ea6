"""Bonded aggregates (issue #32 item 1): an aggregate as its lattice balls held by breakable
parallel bonds instead of a rigid clump, so that fracture can run through the stones (seed 000,
step 3: "a rigid clump, or a cluster held by breakable bonds").

The ``mastic`` stage's key ``aggregates`` picks the model inside an aggregate and stores it in
the phase table (``phases/internal_model``: ``rigid_clump`` or ``parallel_bond``, and for the
latter ``phases/internal_params``). A test stage that bonds its specimen by the table
(``bonds: {from_phases: true, create: true}``) then releases each aggregate's members as free
spheres (:func:`release`) and bonds every pair of lattice neighbours of the same aggregate with
that parallel bond (:func:`bond_members`); its bonds are the INTERNAL model row of the bond set
(:data:`demcli.engine.bonds.INTERNAL`), counted apart in the records (``intra_*`` columns).

The bond from the stone (:func:`bond_parameters`; docs/asphalt_lab.md, "Bonded aggregates"). The
members sit on a simple cubic lattice of spacing L = 2 r (r the lattice ball radius); a bond of
radius R_b = lambda r (area A_b = pi R_b^2) joins two face neighbours. Pulled along a lattice axis,
each bond carries the force of one lattice cell's face L^2, so with

    sigma_c = sigma_t L^2 / A_b = 4 sigma_t / (pi lambda^2)                      [Pa]
    k_n = kn_b A_b = E L,  kn_b = 2 E / (pi lambda^2 r)                          [Pa/m]
    ks_b = kn_b / (2 (1 + nu))                                                   [Pa/m]
    tau_c = shear_ratio sigma_c                                                  [Pa]

the lattice has the stone's Young's modulus E along its axes (a column of springs k_n of length
L per cell face L^2: E_lattice = k_n / L) and fails in uniaxial tension at the stone's tensile
strength sigma_t (tested: tests/stages/test_bonded_aggregates.py). The shear stiffness takes the
ratio G / E = 1 / (2 (1 + nu)) of an isotropic solid. sigma_t is given (``tensile_strength``) or
follows from a single-particle crushing test, a grain of size d split between flat platens at
the force F: sigma_t = F / d^2 (the characteristic tensile stress of Jaeger 1967, as used by
McDowell & Bolton 1998, "On the micromechanics of crushable aggregates", Geotechnique 48(5)
667-679). Not calibrated: the lattice is anisotropic (its strength across a lattice diagonal
differs), and the crushing strength of a grain depends on its size (Weibull), which one value
per case ignores.
"""

import math

import numpy as np

from demcli.config.schema import Float, Optional, Section, Tagged
from demcli.errors import InputError

INTERNAL_MODELS = {"rigid": "rigid_clump", "bonded": "parallel_bond"}


def _check_bonded(node, report):
    """Exactly one of tensile_strength and crushing."""
    if (node.tensile_strength is None) == (node.crushing is None):
        report("tensile_strength", "give exactly one of tensile_strength and crushing",
               node.tensile_strength)


AGGREGATES = Tagged("model", {
    "rigid": Section({}, doc="each aggregate a rigid clump of its lattice balls (no contacts inside)"),
    "bonded": Section({
        "tensile_strength": Optional(Float("Pa", min=0, min_inclusive=False),
                                     doc="tensile strength sigma_t of the stone"),
        "crushing": Optional(Section({
            "force": Float("N", min=0, min_inclusive=False, doc="force F that splits the grain"),
            "size": Float("m", min=0, min_inclusive=False, doc="grain size d between the platens"),
        }), doc="a single-particle crushing test: sigma_t = F / d^2 (Jaeger 1967; McDowell & Bolton 1998)"),
        "young": Optional(Float("Pa", min=0, min_inclusive=False),
                          doc="Young's modulus of the stone for the bond stiffness (default: the aggregate "
                              "material's); a softer stone allows a longer time step (dt ~ 1 / sqrt(E))"),
        "shear_ratio": Float(min=0, min_inclusive=False, default=1.0,
                             doc="bond shear strength / bond normal strength"),
        "radius_multiplier": Float(min=0, max=1, min_inclusive=False, default=1.0,
                                   doc="bond radius / lattice ball radius"),
    }, check=_check_bonded, doc="the lattice balls of each aggregate held by breakable parallel bonds; "
                                "stiffness from the aggregate material's E and nu, strength from sigma_t "
                                "(docs/asphalt_lab.md, 'Bonded aggregates')"),
}, default={"model": "rigid"}, doc="inside an aggregate: rigid clump, or bonded lattice balls whose bonds break")


def tensile_strength(cfg):
    """sigma_t [Pa] of a ``bonded`` aggregates config: given, or F / d^2 of its crushing test."""
    if cfg.tensile_strength is not None:
        return float(cfg.tensile_strength)
    return float(cfg.crushing.force) / float(cfg.crushing.size) ** 2


def bond_parameters(young, poisson, radius, sigma_t, shear_ratio=1.0, radius_multiplier=1.0):
    """Parallel-bond parameters of a simple cubic lattice of balls (radius ``radius`` [m], spacing
    2 r) standing for a stone of Young's modulus ``young`` [Pa], Poisson's ratio ``poisson`` and
    tensile strength ``sigma_t`` [Pa] (module doc): {bond_kn, bond_ks [Pa/m], radius_multiplier,
    normal_strength, shear_strength [Pa]}.

    kn_b = 2 E / (pi lambda^2 r), ks_b = kn_b / (2 (1 + nu)), sigma_c = 4 sigma_t / (pi lambda^2),
    tau_c = shear_ratio sigma_c.
    """
    lam2 = radius_multiplier ** 2
    kn = 2.0 * young / (math.pi * lam2 * radius)
    sigma_c = 4.0 * sigma_t / (math.pi * lam2)
    return {"bond_kn": kn, "bond_ks": kn / (2.0 * (1.0 + poisson)), "radius_multiplier": radius_multiplier,
            "normal_strength": sigma_c, "shear_strength": shear_ratio * sigma_c}


def internal_bond(groups):
    """The parallel-bond parameters of a phase table's bonded aggregates (:func:`bond_parameters`'
    keys), or None for rigid ones; an InputError when the stored parameters are incomplete."""
    from demcli.stages.asphalt.common import scalar_str
    from demcli.stages.asphalt.mastic import str_list

    g = groups.get("phases")
    if g is None or scalar_str(g["internal_model"]) != INTERNAL_MODELS["bonded"]:
        return None
    names = str_list(g["param_names"])
    prm = np.asarray(g.get("internal_params", np.full(len(names), np.nan)), float).reshape(-1)
    cols = {"bond_kn": "pb_kn", "bond_ks": "pb_ks", "radius_multiplier": "pb_radius_multiplier",
            "normal_strength": "pb_normal_strength", "shear_strength": "pb_shear_strength"}
    out = {k: float(prm[names.index(c)]) if c in names and len(prm) == len(names) else math.nan
           for k, c in cols.items()}
    bad = [k for k, v in out.items() if not (math.isfinite(v) and v > 0)]
    if bad:
        raise InputError(f"phases/internal_params: the bonded aggregates' {', '.join(bad)} must be > 0 "
                         f"(got {', '.join(str(out[k]) for k in bad)})")
    return out


def release(groups):
    """State groups with every sphere its own body (sphere k is body k), and the aggregate of
    each sphere (-1: not in an aggregate).

    A member of an aggregate keeps its world position, the velocity of its point of the clump,
    v + omega x d [m/s], the clump's spin and orientation, its share of the clump's mass
    m_e = M / n [kg] and the moments of its element, m_e a^2 / 6 (mass model ``cells``: a cube of
    side a = 2 r) or 2/5 m_e r^2 (``balls``) [kg m^2], so that mass and, about each member, inertia
    add up to the clump's (docs/asphalt3d.md, mass model). Other spheres (mastic balls, single-
    sphere bodies) keep their body's mass and inertia. Contacts and bonds index spheres, whose
    order is kept, so they carry over. The ``aggregates`` group (of the clumps) is left out.
    """
    from demcli.stages.asphalt.common import phase_of_spheres, quat_matrix, scalar_str
    from demcli.state import State

    b, s = groups["bodies"], groups["spheres"]
    sb = np.asarray(s["body"], np.int64)
    agg = phase_of_spheres(State(groups=groups))
    count = np.bincount(sb, minlength=len(b["mass"]))
    rot = quat_matrix(b["q"])[sb]
    d = np.einsum("kij,kj->ki", rot, np.asarray(s["offset"], float))
    omega = np.asarray(b["omega"], float)[sb]
    mass = np.asarray(b["mass"], float)[sb] / count[sb]
    ag = groups["aggregates"]
    r = float(np.asarray(ag["ball_radius"]))
    c = (2.0 * r) ** 2 / 6.0 if scalar_str(ag["mass_model"]) == "cells" else 0.4 * r * r
    inertia = np.where((agg >= 0)[:, None], (mass * c)[:, None], np.asarray(b["inertia"], float)[sb])
    n = len(sb)
    bodies = {"x": np.asarray(b["x"], float)[sb] + d, "v": np.asarray(b["v"], float)[sb] + np.cross(omega, d),
              "q": np.asarray(b["q"], float)[sb], "omega": omega, "mass": mass, "inertia": inertia,
              "id": np.arange(n, dtype=np.int64), "flags": np.asarray(b["flags"])[sb]}
    spheres = {**s, "body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3))}
    # the aggregates group describes clumps, which are gone
    out = {k: v for k, v in groups.items() if k != "aggregates"}
    return {**out, "bodies": bodies, "spheres": spheres}, agg


def member_pairs(x, agg, spacing, tol=1e-6):
    """(i, j) with i < j: the pairs of spheres of the same aggregate (``agg`` >= 0, (n,)) whose
    centres ``x`` (n, 3) [m] are one lattice ``spacing`` [m] apart (face neighbours, touching),
    within ``tol`` x spacing."""
    from scipy.spatial import cKDTree

    mine = np.flatnonzero(agg >= 0)
    if len(mine) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pairs = cKDTree(x[mine]).query_pairs(spacing * (1.0 + tol), output_type="ndarray")
    i, j = mine[pairs[:, 0]], mine[pairs[:, 1]]
    d = np.linalg.norm(x[i] - x[j], axis=1)
    keep = (agg[i] == agg[j]) & (np.abs(d - spacing) <= tol * spacing)
    i, j = np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])
    order = np.lexsort((j, i))
    return i[order], j[order]


def bond_members(system, agg, params):
    """Bond the face neighbours of each aggregate (``agg``: aggregate of each sphere, from
    :func:`release`) with the parallel bond ``params`` (:func:`bond_parameters`' keys) as the
    bond set's INTERNAL model; returns the number of bonds."""
    from demcli.engine.bonds import model_row

    row = system.bonds.internal_model(model_row("parallel_bond", **params))
    spacing = 2.0 * float(np.max(system.rad[agg >= 0])) if np.any(agg >= 0) else 0.0
    i, j = member_pairs(system.xs, agg, spacing)
    return system.bond_pairs(i, j, row)


def prepare(ctx, cfg, groups, resume):
    """(groups, pending) for a stage's system: with bonded aggregates in the input's phase table
    and ``bonds: {from_phases: true, create: true}`` on a fresh start, the released groups and
    (aggregate of each sphere, bond parameters) for :func:`bond_members`; else the groups as they
    are and None (a resumed stage's checkpoint holds the released spheres and their bonds)."""
    bonds = cfg.get("bonds")
    if bonds is None or not bonds.from_phases or resume:
        return groups, None
    try:
        params = internal_bond(groups)
    except InputError as e:
        raise InputError(f"stage {ctx.name}: {e}") from None
    if params is None:
        return groups, None
    if not bonds.create:
        raise InputError(f"stage {ctx.name}: the phase table's aggregates are bonded: give bonds.create: true to "
                         "release their balls and bond them")
    released, agg = release(groups)
    return released, (agg, params)
