"""Registry of the physical effects a stage can declare (see :mod:`demcli.effects.registry`)."""

from demcli.effects.registry import (EFFECTS, SHAPES, EffectSpec, check_shape, declared, effects_table,
                                     physics_section, register, shape_refusals)

__all__ = ["EFFECTS", "SHAPES", "EffectSpec", "check_shape", "declared", "effects_table", "physics_section",
           "register", "shape_refusals"]
