"""Compile-time switches of the engine: a group of arrays that a scene lacks is passed as None.

Numba specialises a kernel for the types of its arguments and prunes an ``if x is None:``
branch before typing when the argument ``x`` *is* None, so code that only a present group
needs (the bond passes, the clump member pass, the rigid rotor's kick, the fused kick of spin
rotors) is not compiled for a scene without it. The converse is not pruned: with ``x`` an
array both branches are compiled (correct, only not smaller). A function that must return
either None or an array by the type of its input cannot be written with ``if x is None`` (numba
would type its result Optional and check it at run time); :func:`choose` decides on the type
instead.
"""

from numba import types
from numba.extending import overload


def choose(switch, if_none, otherwise):
    """``if_none`` when ``switch`` is None, else ``otherwise``; decided at compile time from the
    type of ``switch`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return if_none if switch is None else otherwise


@overload(choose, inline="always")
def _choose(switch, if_none, otherwise):
    if isinstance(switch, types.NoneType):
        return lambda switch, if_none, otherwise: if_none
    return lambda switch, if_none, otherwise: otherwise
