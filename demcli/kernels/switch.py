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

from demcli.kernels.layout import F_ADAPTIVE, F_ENERGY, F_PLANAR, F_VISCOUS

STATIC = (F_VISCOUS, F_ENERGY, F_PLANAR, F_ADAPTIVE)
"""The kernel switches (layout.F_*) that most scenes leave off and whose branches sit in the
per-body and per-contact loops. run_steps takes them as one int (:func:`static_mask`),
omitted when none is on: numba then types it as the constant 0 (an omitted argument's
default), passes it on as ``Literal[int](0)``, and :func:`on` reads each switch as a constant
False, so the common scene runs without their branches (dense_10000: +6.5 % on one thread).
A scene with one of them on runs the variant that reads them at run time. Two variants at
most, not one per combination: compiling every combination (``numba.literally``) made the
test suite compile so many engines that it passed 13 minutes at 60 % (it takes 7.5)."""


def static_mask(flags):
    """The int of the :data:`STATIC` switches that ``flags`` (the plan's tuple) has on."""
    return sum(1 << k for k in STATIC if flags[k])


def on(mask, k):
    """Whether switch k is on in ``mask``; a constant when ``mask`` is a literal (plain Python:
    with NUMBA_DISABLE_JIT=1)."""
    return bool(mask >> k & 1)


@overload(on, inline="always")
def _on(mask, k):
    value = mask.value if isinstance(mask, types.Omitted) else getattr(mask, "literal_value", None)
    if isinstance(value, int) and isinstance(k, types.IntegerLiteral):
        if value >> k.literal_value & 1:
            return lambda mask, k: True
        return lambda mask, k: False
    return lambda mask, k: mask >> k & 1 != 0


def choose(switch, if_none, otherwise):
    """``if_none`` when ``switch`` is None, else ``otherwise``; decided at compile time from the
    type of ``switch`` (plain Python: with NUMBA_DISABLE_JIT=1)."""
    return if_none if switch is None else otherwise


@overload(choose, inline="always")
def _choose(switch, if_none, otherwise):
    if isinstance(switch, types.NoneType):
        return lambda switch, if_none, otherwise: if_none
    return lambda switch, if_none, otherwise: otherwise
