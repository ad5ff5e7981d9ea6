"""Shape plug-ins of the body engine, chosen at compile time by the type of the geometry tuple.

A shape module defines a named tuple class for its geometry arrays and the hooks below as
numba (``njit``) functions; :func:`register` maps the class to the module. The engine
(:mod:`demcli.kernels.engine`) calls the stubs here; numba specialises the engine for each
geometry type and calls the registered shape's hook (``numba.extending.overload``), so a
scene compiles only its own shape's passes and pays no dispatch at run time. Every hook is a
pass called once per step: it takes the arrays out of the tuples and hands them to its
parallel loop. Two numba 0.68 traps this avoids: an inlined function that writes arrays taken
from a tuple inside a prange body loses the writes, and a plain call per body or per contact
that passes tuples of arrays pays an atomic reference-count update per array (a 6x slowdown
of the sphere gather when the wall contact was such a call).

Hooks (g: the geometry tuple, bd: Bodies, nl: Contacts, wa: WallArrays; see
:mod:`demcli.kernels.layout`):

* ``place(g, bd, flags, xref, lim2, rebuild)``: bring the primitives to the bodies' new pose
  (clump members, polyhedron world vertices), flag a list rebuild if one moved > skin/2;
* ``volumetric(g)``: whether contacts keep a depth and a separation cache (geo, sep, sdir) and
  normal forces turn the bodies (polyhedra);
* ``primitives(g, bd)``: (positions, radii, body of each) of the spheres the Verlet lists
  are built on (the spheres themselves, or bounding spheres);
* ``pair_pass(g, bd, nl, prm, law, flags, dt, frow, trow, erow, bonds, bprm, broke)``: the force
  of every listed pair into its own row, the row owner's sums into frow/trow/erow;
* ``wall_pass(g, bd, nl, wa, prm, law, flags, dt)``: every primitive-wall contact k into its own
  rows: nl.wfc[k] (force on the primitive, servo stiffness, normal force), nl.wtq[k] (torque),
  nl.wen[k] (dashpot and slip losses, with energy);
* ``worst_overlap(g, nl, wa)``: (ratio, i, j) for the guard;
* ``spin_rotors(g, mb, xref)``: ``xref`` when every body is one sphere (spin rotors: the gather
  fuses their next kick and drift), else None; the engine's compile-time switch (numba prunes
  the fused path from the gather of clumps and polyhedra).
"""

import inspect

from numba.extending import overload

from demcli.jit import INTERNAL

from demcli.kernels.shapes import mixed, polyhedra, spheres

SHAPES = {}


def register(geometry_class, module):
    """Make ``module``'s hooks the implementation for geometry tuples of ``geometry_class``."""
    SHAPES[geometry_class] = module


register(spheres.SphereGeometry, spheres)
register(polyhedra.PolyGeometry, polyhedra)
register(mixed.MixedGeometry, mixed)


def _hook(g, name):
    """The registered shape's hook ``name`` for the numba type ``g`` of a geometry tuple."""
    cls = getattr(g, "instance_class", None)
    if cls not in SHAPES:
        raise TypeError(f"no shape plug-in registered for {g}")
    return getattr(SHAPES[cls], name)


def place(g, bd, flags, xref, lim2, rebuild):
    """The shape's ``place`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "place")(g, bd, flags, xref, lim2, rebuild)


def volumetric(g):
    """The shape's ``volumetric`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "volumetric")(g)


def primitives(g, bd):
    """The shape's ``primitives`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "primitives")(g, bd)


def pair_pass(g, bd, nl, prm, law, flags, dt, frow, trow, erow, bonds, bprm, broke):
    """The shape's ``pair_pass`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "pair_pass")(g, bd, nl, prm, law, flags, dt, frow, trow, erow, bonds, bprm, broke)


def wall_pass(g, bd, nl, wa, prm, law, flags, dt):
    """The shape's ``wall_pass`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "wall_pass")(g, bd, nl, wa, prm, law, flags, dt)


def worst_overlap(g, nl, wa):
    """The shape's ``worst_overlap`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "worst_overlap")(g, nl, wa)


def spin_rotors(g, mb, xref):
    """The shape's ``spin_rotors`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return getattr(SHAPES[type(g)], "spin_rotors")(g, mb, xref)


def _implement(name, inline="never"):
    """Overload the engine's entry point ``name`` (the plain-Python function above) with the
    registered shape's hook, compiled in the caller's context: the overload returns the hook's
    Python function, so numba compiles it once as the entry point's implementation (not a wrapper
    lambda that calls the separately compiled hook: one function fewer per pass to compile and to
    link, ~3 s of the polyhedral engine's cold JIT)."""
    entry = globals()[name]

    def typer(*args):
        return _hook(args[0], name).py_func

    typer.__signature__ = inspect.signature(entry)
    overload(entry, inline=inline, jit_options=dict(INTERNAL))(typer)  # called by the engine only


for _name in ("place", "primitives", "pair_pass", "wall_pass", "worst_overlap", "spin_rotors"):
    _implement(_name)
_implement("volumetric", inline="always")
