"""The effects a stage can declare, and what each costs when it is active.

Each :class:`EffectSpec` names the arrays the plan allocates for it and the kernel
passes that run for it (LAMMPS-style declared hooks). An effect a stage does not
declare allocates nothing and runs nothing: the plan leaves its arrays at size zero
and the kernel's switch for it off; the kernel's pass counters prove it.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class EffectSpec:
    name: str
    doc: str
    fields: tuple = ()     # (array name, rows per: 'pair' | 'wall_pair' | 'sphere' | 'body' | 'wall')
    passes: tuple = ()     # kernel passes it adds
    counters: tuple = ()   # names of kernel pass counters that prove it ran


EFFECTS = {}


def register(spec):
    """Add an effect to the registry (one file per effect family may call this)."""
    if spec.name in EFFECTS:
        raise ValueError(f"effect {spec.name!r} registered twice")
    EFFECTS[spec.name] = spec
    return spec


register(EffectSpec(
    "gravity", "uniform body force m g",
    passes=("body_loads:gravity",), counters=("gravity",)))
register(EffectSpec(
    "friction", "tangential spring with Coulomb slip; bodies rotate",
    fields=(("contact_ft", "pair"), ("wall_ft", "wall_pair"), ("torque_i", "pair"), ("torque_j", "pair")),
    passes=("pairs:tangential", "kick:rotation"), counters=("friction",)))
register(EffectSpec(
    "rolling_resistance", "elastic-plastic rolling spring (Ai et al. 2011, model C)",
    fields=(("contact_mr", "pair"), ("wall_mr", "wall_pair"), ("torque_i", "pair"), ("torque_j", "pair")),
    passes=("pairs:rolling", "kick:rotation"), counters=("rolling",)))
register(EffectSpec(
    "local_damping", "Cundall non-viscous damping -lambda |F| sign(v)",
    passes=("body_loads:local_damping",), counters=("damping",)))
register(EffectSpec(
    "viscous_damping", "mass-proportional damping -alpha m v",
    passes=("body_loads:viscous_damping",), counters=("damping",)))
register(EffectSpec(
    "walls", "rigid plane and cylinder walls with velocity, force or servo control",
    fields=(("wall_list", "wall_pair"), ("wall_force", "wall")),
    passes=("walls:move", "walls:list", "walls:control"), counters=("wallmove", "wallctrl")))
register(EffectSpec(
    "energy", "energy book-keeping: dashpot, slip and damping losses, wall work",
    fields=(("pair_losses", "pair"), ("sphere_losses", "sphere"), ("body_losses", "body")),
    passes=("pairs:losses", "gather:losses"), counters=("energy",)))
register(EffectSpec(
    "planar", "2D mode: z and out-of-plane rotations locked (disks, mass per unit thickness)",
    passes=("kick:planar_lock",)))
register(EffectSpec(
    "clumps", "rigid bodies of several spheres (derived from the state, not declared)",
    fields=(("orientation", "body"), ("angular_momentum", "body"), ("member_csr", "sphere"),
            ("sphere_kinematics", "sphere")),
    passes=("members:place", "bodies:sum_members"), counters=("members", "body")))
register(EffectSpec(
    "polyhedra", "rigid convex polyhedra (derived from the state): exact overlap-volume contacts",
    fields=(("world_vertices", "body"), ("world_planes", "body"), ("contact_ft", "pair")),
    passes=("polyhedra:world_geometry", "pairs:overlap_volume"), counters=("pairs",)))
register(EffectSpec(
    "adaptive_damping", "mass-proportional damping whose alpha adapts by R = E_a / |dE_k| (Shao et al. 2017)",
    passes=("body_loads:adaptive_damping",), counters=("damping",)))
register(EffectSpec(
    "contact_damping", "polyhedra: normal dashpot c_n = 2 zeta sqrt(m* k_n sqrt(A)) from the material restitution",
    passes=("pairs:contact_damping",)))
register(EffectSpec(
    "bonds", "contact, parallel and Burgers bonds between spheres (declared by a stage that creates them, "
    "derived from a state that holds them)",
    fields=(("bond_list", "bond"), ("bond_history", "bond"), ("bond_force", "bond"), ("torque_i", "pair")),
    passes=("bonds:forces", "bonds:gather", "kick:rotation"), counters=("bonds",)))
