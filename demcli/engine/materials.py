"""Material-pair contact table and the critical time step.

Mixing rules (the defaults; a case can override any pair):

* effective moduli (Hertz): 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2,
  1/G* = (2-nu1)/G1 + (2-nu2)/G2 (Johnson 1985, ch. 4 and 7), with G = E / (2(1+nu)) unless a
  material gives its shear modulus; a rigid material (a wall with ``rigid: true``, its twin
  from :func:`with_rigid_twins`) adds no compliance: E* = E1/(1-nu1^2), G* = G1/(2-nu1);
* friction, rolling friction and restitution: geometric mean of the two materials;
* damping ratio from restitution: zeta = -ln e / sqrt(pi^2 + ln^2 e).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from demcli.kernels.contact import (HERTZ, LINEAR, N_PARAMS, P_ARM, P_CN, P_CTR, P_ESTAR, P_GSTAR, P_KN,
                                    P_KT, P_MU, P_MUR, P_NOTENSION, P_ZETA)

LAWS = {"linear": LINEAR, "hertz_mindlin": HERTZ}


@dataclass(frozen=True)
class Material:
    """Bulk properties of one material (SI)."""

    name: str
    density: float          # kg/m^3
    young: float = 1e9      # Pa
    poisson: float = 0.3    # -
    friction: float = 0.5   # -
    rolling_friction: float = 0.0  # -
    restitution: float = 0.5       # -
    shear: float = None            # Pa; None: E / (2 (1 + nu))
    rigid: bool = False            # no compliance in E*, G* (rigid walls)

    def compliances(self):
        """((1 - nu^2)/E, (2 - nu)/G) [1/Pa], the material's terms of 1/E* and 1/G*; 0 when rigid."""
        if self.rigid:
            return 0.0, 0.0
        if self.shear is None:
            return (1 - self.poisson ** 2) / self.young, 2 * (2 - self.poisson) * (1 + self.poisson) / self.young
        return (1 - self.poisson ** 2) / self.young, (2 - self.poisson) / self.shear

    def shear_modulus(self):
        """G [Pa]: the given one, or E / (2 (1 + nu))."""
        return self.young / (2 * (1 + self.poisson)) if self.shear is None else self.shear


@dataclass(frozen=True)
class ContactModel:
    """Stage-level contact law settings (SI)."""

    law: str = "hertz_mindlin"           # 'linear' or 'hertz_mindlin'
    kn: float = 0.0                      # linear normal stiffness [N/m]
    kt: float = 0.0                      # linear tangential stiffness [N/m]
    cn: float = 0.0                      # absolute normal damping [N s/m]; when > 0 restitution is not used
    tangential_damping: float = 0.0      # c_t / c_n ratio
    no_tension: bool = False             # clip the normal force at 0 (kernels/contact.py)
    lever_arm: str = "deformed"          # 'deformed' (R - delta/2) or 'radius' (R)
    pairs: tuple = field(default_factory=tuple)  # ((mat_a, mat_b, {key: value}), ...)
    geometry_refresh: int = 1            # polyhedra: exact intersection every k-th step, linearized between


def damping_ratio(e):
    """zeta(e) = -ln e / sqrt(pi^2 + ln^2 e); e in (0, 1]."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return -le / math.sqrt(math.pi ** 2 + le * le)


RIGID_SUFFIX = " (rigid)"


def with_rigid_twins(materials):
    """The materials followed by a rigid twin of each (same friction, restitution, name + " (rigid)"):
    a wall with ``rigid: true`` of material k uses material n + k."""
    import dataclasses

    return list(materials) + [dataclasses.replace(m, name=m.name + RIGID_SUFFIX, rigid=True) for m in materials]


def wall_materials(materials, material, rigid):
    """(n_w,) int64 material index of each wall for the contact tables: ``material`` (indices
    into ``materials``), a rigid wall's moved to its material's rigid twin (:func:`with_rigid_twins`).
    ``rigid``: (n_w,) bool or None (none rigid)."""
    out = np.array(material, dtype=np.int64)
    if rigid is not None:
        names = [m.name for m in materials]
        for k in np.flatnonzero(rigid):
            twin = materials[out[k]].name + RIGID_SUFFIX
            if twin not in names:
                raise ValueError(f"wall {k} is rigid but the materials have no {twin!r} (materials.with_rigid_twins)")
            out[k] = names.index(twin)
    return out


def pair_table(materials, model):
    """(n_m, n_m, N_PARAMS) float64 table of contact parameters for every material pair."""
    n = len(materials)
    prm = np.zeros((n, n, N_PARAMS))
    names = [m.name for m in materials]
    overrides = {}
    for a, b, values in model.pairs:
        ia, ib = names.index(a), names.index(b)
        overrides[(ia, ib)] = overrides[(ib, ia)] = dict(values)
    for i, mi in enumerate(materials):
        for j, mj in enumerate(materials):
            o = overrides.get((i, j), {})
            mu = o.get("friction", math.sqrt(mi.friction * mj.friction))
            mur = o.get("rolling_friction", math.sqrt(mi.rolling_friction * mj.rolling_friction))
            e = o.get("restitution", math.sqrt(mi.restitution * mj.restitution))
            row = prm[i, j]
            row[P_MU] = mu
            row[P_MUR] = mur
            row[P_CTR] = model.tangential_damping
            row[P_NOTENSION] = 1.0 if model.no_tension else 0.0
            row[P_ARM] = 1.0 if model.lever_arm == "deformed" else 0.0
            (ei, gi), (ej, gj) = mi.compliances(), mj.compliances()
            row[P_ESTAR] = 1.0 / (ei + ej) if ei + ej > 0.0 else math.inf  # two rigid materials
            row[P_GSTAR] = 1.0 / (gi + gj) if gi + gj > 0.0 else math.inf
            if model.law == "linear":
                row[P_KN] = o.get("kn", model.kn)
                row[P_KT] = o.get("kt", model.kt)
                row[P_CN] = o.get("cn", model.cn)
                row[P_ZETA] = 0.0 if row[P_CN] > 0 else damping_ratio(e)
            else:
                row[P_ZETA] = damping_ratio(e)
    return prm


def critical_time_step(model, prm, materials, body_mass, sphere_radius, sphere_body, sphere_material):
    """Critical step [s] of the explicit integrator for this scene and contact law.

    linear: 2 / omega_max, with omega^2 = k_n / m* for the lightest wall contact (m* = m;
    a sphere pair, m* = m/2, gives 2 k_n / m) and omega^2 = k_t (1/m_i + 1/m_j + r_i^2/I_i
    + r_j^2/I_j) = 7 k_t / m for the mode of a pair that the tangential spring moves and
    turns (I = 2/5 m r^2); hertz_mindlin: the Rayleigh wave step
    pi r sqrt(rho / G) / (0.1631 nu + 0.8766) of the smallest sphere of each material
    (Li, Xu & Thornton 2005).
    """
    if len(sphere_radius) == 0:
        return math.inf
    if model.law == "linear":
        kn = prm[..., P_KN].max()
        kt = prm[..., P_KT].max()
        mmin = body_mass[sphere_body].min()
        w2 = max(2 * kn / mmin, 7 * kt / mmin)
        return 2.0 / math.sqrt(w2) if w2 > 0 else math.inf
    best = math.inf
    for k in np.unique(sphere_material):
        mat = materials[k]
        r = sphere_radius[sphere_material == k].min()
        shear = mat.shear_modulus()
        best = min(best, math.pi * r * math.sqrt(mat.density / shear) / (0.1631 * mat.poisson + 0.8766))
    return best
