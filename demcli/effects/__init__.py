"""Registry of the physical effects a stage can declare (see :mod:`demcli.effects.registry`)."""

from demcli.effects.registry import EFFECTS, EffectSpec, register

__all__ = ["EFFECTS", "EffectSpec", "register"]
