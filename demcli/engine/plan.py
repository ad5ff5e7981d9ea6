"""The plan: which passes run and which arrays exist, derived from the declared effects.

The scene file is the only switchboard: a stage declares its effects, the state says
whether clumps or walls exist, and :func:`make_plan` turns that into the kernel's
switches, the list of passes and the list of allocated arrays. Nothing else reads a
flag to decide what exists.
"""

from dataclasses import dataclass

from demcli.effects import EFFECTS
from demcli.kernels import layout as K

BASE_PASSES = ("kick:translation", "neighbors:rebuild", "pairs:normal", "gather:forces",
               "check:guards")
BASE_FIELDS = (("x", "body"), ("v", "body"), ("omega", "body"), ("force", "body"), ("torque", "body"),
               ("pair_csr", "pair"), ("pair_force", "pair"), ("pair_active", "pair"))


@dataclass(frozen=True)
class Plan:
    """Active effects, kernel switches, passes and allocated arrays of one stage."""

    effects: frozenset
    flags: tuple
    passes: tuple
    fields: tuple

    def has(self, name):
        return name in self.effects

    def describe(self):
        """Human-readable summary for ``demcli check``."""
        lines = ["effects: " + (", ".join(sorted(self.effects)) or "(none)"),
                 "passes:  " + ", ".join(self.passes),
                 "arrays:  " + ", ".join(f"{n}[{per}]" for n, per in self.fields)]
        return "\n".join(lines)


def make_plan(declared, clumps=False, walls=False, polyhedra=False, bonds=False):
    """Plan for the declared effect names plus what the state implies.

    Args:
        declared: iterable of effect names the stage declares (keys of EFFECTS).
        clumps: the state holds bodies made of several spheres.
        walls: the stage has walls.
        polyhedra: the state's bodies are convex polyhedra.
        bonds: the state holds bonds.
    """
    active = set(declared)
    unknown = active - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown effects: {sorted(unknown)}")
    if polyhedra:
        active.add("polyhedra")
    elif clumps:
        active.add("clumps")
    if walls:
        active.add("walls")
    if bonds:
        active.add("bonds")
    passes = list(BASE_PASSES)
    fields = list(BASE_FIELDS)
    for name in sorted(active):
        spec = EFFECTS[name]
        passes += [p for p in spec.passes if p not in passes]
        fields += [f for f in spec.fields if f not in fields]
    flags = [False] * K.N_FLAGS
    flags[K.F_CLUMPS] = "clumps" in active
    flags[K.F_FRICTION] = "friction" in active
    flags[K.F_ROLLING] = "rolling_resistance" in active
    flags[K.F_ENERGY] = "energy" in active
    flags[K.F_PLANAR] = "planar" in active
    flags[K.F_GRAVITY] = "gravity" in active
    flags[K.F_LOCAL] = "local_damping" in active
    flags[K.F_VISCOUS] = "viscous_damping" in active
    flags[K.F_WALLS] = "walls" in active
    flags[K.F_BONDS] = "bonds" in active
    return Plan(frozenset(active), tuple(flags), tuple(passes), tuple(fields))
