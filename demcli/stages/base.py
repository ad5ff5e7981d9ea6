"""Stage types: each is a config schema plus a run function, registered by name.

A stage type module calls :func:`register_stage` at import; the case schema is built
from the registry, so a new stage is one new module and nothing else changes.
"""

from dataclasses import dataclass

STAGE_TYPES = {}


@dataclass(frozen=True)
class StageType:
    """A kind of stage.

    Attributes:
        name: the ``type:`` value in a case file.
        fields: dict of schema fields of the stage (besides ``name`` and ``type``).
        run: ``run(ctx, cfg, state_in) -> State``.
        needs_input: the stage reads the previous stage's state.
        requires: state fields the input must hold (checked before running).
        plan: optional ``plan(cfg, case) -> Plan`` for ``demcli check``.
        check: optional cross-field rule ``check(node, report)``.
        doc: one-line description.
        describe: optional ``describe(cfg, case) -> str`` summary for ``demcli check``.
        orders_particles: the runner re-stores the input scene in spatial cell order before
            the stage (and before hashing it) where :func:`demcli.state.order.spatial_order`
            can: spheres, and no contacts, bonds, actors or checkpoint yet. Set by the stages
            that integrate a sphere scene from its first step (dem, compact).
    """

    name: str
    fields: dict
    run: object
    needs_input: bool = True
    requires: tuple = ()
    plan: object = None
    check: object = None
    doc: str = ""
    describe: object = None
    orders_particles: bool = False


def register_stage(stage_type):
    if stage_type.name in STAGE_TYPES:
        raise ValueError(f"stage type {stage_type.name!r} registered twice")
    STAGE_TYPES[stage_type.name] = stage_type
    return stage_type


def load_stage_types():
    """Import every built-in stage module (registers them) and return the registry."""
    from demcli.stages import dem, generate, gradation  # noqa: F401
    from demcli.stages import assemble, ballast_box, ballast_library  # noqa: F401
    from demcli.stages import ballast_clumps  # noqa: F401  (polyhedra as sphere clumps)
    from demcli.stages import discretize, polygons  # noqa: F401  (2D sections, seed 001)
    from demcli.stages import asphalt_carve, asphalt_compact, asphalt_place  # noqa: F401  (3D asphalt, seed 000)
    from demcli.stages import asphalt_cut, asphalt_mastic  # noqa: F401  (3D asphalt, seed 000)
    from demcli.stages import sand_asphalt  # noqa: F401  (bonded viscoelastic specimens, seed 003)

    return STAGE_TYPES
