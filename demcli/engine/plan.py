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

    The implied effects are those whose registry ``source`` is 'walls' or 'bonds', and the
    shape effect of the bodies (clumps, polyhedra); the kernel switches are the ``flag`` of
    every active effect, in the order of ``layout.FLAG_NAMES``.
    """
    active = set(declared)
    unknown = active - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown effects: {sorted(unknown)}")
    shape = "polyhedra" if polyhedra else "clumps" if clumps else "spheres"
    implied = {"walls": walls, "bonds": bonds}
    active |= {s.name for s in EFFECTS.values() if implied.get(s.source) or (s.source == "shape" and s.name == shape)}
    passes = list(BASE_PASSES)
    fields = list(BASE_FIELDS)
    for name in sorted(active):
        spec = EFFECTS[name]
        passes += [p for p in spec.passes if p not in passes]
        fields += [f for f in spec.fields if f not in fields]
    switched = {EFFECTS[name].flag for name in active}
    flags = tuple(name in switched for name in K.FLAG_NAMES)
    return Plan(frozenset(active), flags, tuple(passes), tuple(fields))
