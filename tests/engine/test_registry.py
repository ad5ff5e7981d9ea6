"""The effect registry is the switchboard: schema, plan flags, shape checks and the doc table derive from it."""

import pytest

from demcli.effects import EFFECTS, SHAPES, check_shape, effects_table, physics_section, shape_refusals
from demcli.effects.table import DOC, table_in
from demcli.engine.plan import make_plan
from demcli.errors import InputError
from demcli.kernels import layout as K


def test_the_doc_table_is_the_generated_one():
    # Given docs/architecture.md; Then its effect x shape table is the registry's (python -m demcli.effects.table)
    assert table_in(DOC.read_text()) == "\n" + effects_table()


def test_every_kernel_flag_belongs_to_exactly_one_effect():
    # Given the registry's flags; Then each is a kernel switch, and each switch has exactly one effect
    flags = [s.flag for s in EFFECTS.values() if s.flag]
    assert set(flags) <= set(K.FLAG_NAMES)
    assert sorted(flags) == sorted(K.FLAG_NAMES)
    assert EFFECTS["clumps"].source == "shape"  # the clumps switch comes from the state, not a declaration


def test_the_physics_schema_is_the_registered_keys():
    # Given the dem stage's physics section; Then its keys are the registered ones, in registration order
    from demcli.stages.dem import FIELDS

    keys = [s.key for s in EFFECTS.values() if s.key]
    assert list(FIELDS["physics"].fields) == keys == list(physics_section().fields)
    assert keys == ["gravity", "friction", "rolling_resistance", "local_damping", "viscous_damping",
                    "contact_damping", "adaptive_damping", "energy"]


def test_every_unsupported_shape_says_why():
    for s in EFFECTS.values():
        assert set(s.unsupported) <= set(SHAPES)
        assert all(isinstance(why, str) and why for why in s.unsupported.values()), s.name


def _on(plan):
    return {name for name, on in zip(K.FLAG_NAMES, plan.flags) if on}


@pytest.mark.parametrize("declared, state, on", [
    ((), {}, set()),
    (("gravity", "friction"), {}, {"gravity", "friction"}),
    (("gravity", "local_damping", "viscous_damping", "energy", "rolling_resistance", "planar"), {"clumps": True},
     {"gravity", "local", "viscous", "energy", "rolling", "planar", "clumps"}),
    (("friction",), {"walls": True, "bonds": True}, {"friction", "bonds"}),  # walls have no switch
    (("contact_damping", "adaptive_damping"), {"polyhedra": True, "clumps": True}, {"dashpot", "adaptive"}),
])
def test_plan_flags_are_the_active_effects_switches(declared, state, on):
    # When a plan is made; Then its flags tuple is in FLAG_NAMES order and on exactly for the active effects
    plan = make_plan(declared, **state)
    assert len(plan.flags) == K.N_FLAGS and all(type(f) is bool for f in plan.flags)
    assert _on(plan) == on
    assert ("walls" in plan.effects) == state.get("walls", False)
    assert ("polyhedra" in plan.effects) == state.get("polyhedra", False)


def test_declared_effects_follow_the_physics_section():
    # Given a physics section with a zero local damping (which declares it) and friction off
    from demcli.config.schema import Section, validate_quietly
    from demcli.stages.dem import FIELDS, declared_effects

    node = validate_quietly(Section({"physics": FIELDS["physics"]}),
                            {"physics": {"gravity": [0, 0, -9.81], "friction": False, "local_damping": 0.0}})
    # Then gravity and local damping are declared, and planar in 2D
    assert declared_effects(node, 3) == ["gravity", "local_damping"]
    assert declared_effects(node, 2) == ["gravity", "local_damping", "planar"]


@pytest.mark.parametrize("effect, shape, where, reason", [
    ("rolling_resistance", "polyhedra", "physics.rolling_resistance", "polyhedra resist rolling by their faces"),
    ("contact_damping", "spheres", "physics.contact_damping", "restitution dashpot always"),
    ("contact_damping", "clumps", "physics.contact_damping", "restitution dashpot always"),
    ("planar", "polyhedra", "dimension: 2 (effect planar)", "made of disks"),
    ("bonds", "polyhedra", "bonds (effect bonds)", "sphere radii and centre lines"),
])
def test_an_effect_on_a_shape_it_does_not_support_is_refused_with_the_reason(effect, shape, where, reason):
    with pytest.raises(InputError) as err:
        check_shape(["gravity", effect], shape, "settle")
    msg = str(err.value.format_message())
    assert msg.startswith(f"stage settle: {where} is not for {shape}: ") and reason in msg


def test_supported_effects_and_shapes_pass():
    for shape in SHAPES:
        names = [n for n, s in EFFECTS.items() if s.supports(shape)]
        check_shape(names, shape, "s")  # (shape effects are skipped)
    # spheres or clumps (demcli check cannot tell them apart): refused only where neither runs
    assert [s.name for s, _ in shape_refusals(["contact_damping", "bonds"], ("spheres", "clumps"))] == \
        ["contact_damping"]
