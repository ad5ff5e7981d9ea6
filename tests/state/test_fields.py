"""Field registry: validation of dtypes, dims, required and unknown fields."""

from pathlib import Path

import numpy as np
import pytest

from demcli.errors import StateError
from demcli.state import (
    Field,
    State,
    check,
    get_rng,
    new_state,
    register,
    register_group,
    require,
    set_rng,
    validate,
)
from demcli.state.fields import FIELDS, GROUPS, example_state


def test_example_state_is_valid():
    # Given the example state with every core group
    state = example_state(rolling=True)
    # When it is checked
    problems = check(state)
    # Then there are no problems
    assert problems == []


def test_inconsistent_dims_name_both_fields():
    # Given a state whose bodies/v has one body fewer than bodies/x
    state = example_state()
    state["bodies/v"] = state["bodies/v"][:-1]
    # When it is validated
    with pytest.raises(StateError) as err:
        validate(state, source="s.h5")
    # Then the message names the dim and both fields
    msg = err.value.format_message()
    assert "s.h5" in msg and "inconsistent n_b" in msg
    assert "bodies/v" in msg and "bodies/x" in msg


def test_wrong_dtype_kind_is_rejected():
    # Given radii stored as integers
    state = example_state()
    state["spheres/radius"] = np.ones(len(state["spheres/radius"]), dtype=np.int64)
    # When checked
    problems = check(state)
    # Then the problem names the field and the expected kind
    assert any("spheres/radius" in p and "float" in p for p in problems)


def test_wrong_trailing_size_is_rejected():
    # Given quaternions with 3 components
    state = example_state()
    state["bodies/q"] = state["bodies/q"][:, :3]
    # When checked / Then the fixed size is reported
    assert any("bodies/q" in p and "(n_b, 4)" in p for p in check(state))


def test_unknown_dataset_in_known_group_is_rejected_with_hint():
    # Given a typo'd dataset in the bodies group
    state = example_state()
    state["bodies/omgea"] = state["bodies/omega"]
    # When checked
    problems = check(state)
    # Then the unknown field and its group are named, with a suggestion
    assert any("unknown dataset 'omgea' in group 'bodies'" in p and "'omega'" in p for p in problems)


def test_unknown_group_is_rejected():
    # Given a group no demcli module registers (every module is imported before saying so)
    state = example_state()
    state["gradation_unregistered/sieve"] = np.array([9.5, 4.75])
    # When checked / Then it is named
    assert check(state) == ["unknown group 'gradation_unregistered' (no demcli stage or effect writes it)"]


def test_group_of_a_stage_not_imported_is_known(tmp_path):
    # Given a state holding the gradation group, read where no stage module was imported
    import subprocess
    import sys

    from demcli import run_case

    case = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "ballast_deposit.yaml"
    run_case(case, out=tmp_path, only="grading", quiet=True)
    code = ("import sys; from demcli.state import read_state; "
            "before = 'demcli.stages.specimen.gradation' in sys.modules; st = read_state(sys.argv[1]); "
            "print(before, sorted(st.groups))")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "00-grading.h5")], capture_output=True,
                         text=True)
    # Then it reads and validates: the registry imports the stage that registers the group
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("False") and "'gradation'" in out.stdout


def test_missing_field_names_writer():
    # Given a state without contacts/force
    state = example_state()
    del state.groups["contacts"]["force"]
    # When validated
    with pytest.raises(StateError) as err:
        validate(state)
    # Then the message names the field and who writes it
    assert "missing field 'contacts/force'" in str(err.value) and "written by engine" in str(err.value)


def test_rolling_moment_required_only_with_rolling_effect():
    # Given a state without contacts/mr
    state = example_state(rolling=False)
    assert "contacts/mr" not in state
    # When the rolling_resistance effect is off, it is valid
    assert check(state) == []
    # When the effect is switched on, the missing moment is reported with its writer
    state.meta["effects"] = state.meta["effects"] + ["rolling_resistance"]
    problems = check(state)
    assert any("contacts/mr" in p and "effect rolling_resistance" in p for p in problems)


def test_index_out_of_range_is_rejected():
    # Given a sphere pointing at a body that does not exist
    state = example_state()
    state["spheres/body"][0] = 99
    # When checked / Then the index field and its range are reported
    assert any("spheres/body" in p and "n_b=4" in p for p in check(state))


def test_missing_required_group_and_meta():
    # Given a state with meta only
    state = new_state("x", "compaction")
    del state.meta["dt"]
    # When checked
    problems = check(state)
    # Then the missing group and the missing meta entry are both named
    assert any("missing group 'bodies'" in p for p in problems)
    assert any("missing meta 'dt'" in p for p in problems)


def test_meta_types_are_checked():
    # Given a step given as a float and effects given as a string
    state = example_state()
    state.meta["step"] = 1.5
    state.meta["effects"] = "gravity"
    problems = check(state)
    # Then both are reported
    assert any("meta/step" in p for p in problems)
    assert any("meta/effects" in p for p in problems)


def test_register_new_group_and_conflict():
    # Given a stage registering its own group and field
    register_group("test_bonds_x", "bonds for a test", writer="effect bonds")
    register(Field("test_bonds_x/i", "i", ("n_bond",), "", "first sphere", index_of="n_s", writer="effect bonds"))
    try:
        # When the same field is registered again identically, nothing happens
        register(Field("test_bonds_x/i", "i", ("n_bond",), "", "first sphere", index_of="n_s",
                       writer="effect bonds"))
        # When registered differently, it is an error
        with pytest.raises(ValueError, match="already registered"):
            register(Field("test_bonds_x/i", "f", ("n_bond",), "", "first sphere"))
        # Then a state using the group is validated against it
        state = example_state()
        state["test_bonds_x/i"] = np.array([0.5])
        assert any("test_bonds_x/i" in p for p in check(state))
    finally:
        FIELDS.pop("test_bonds_x/i", None)
        GROUPS.pop("test_bonds_x", None)


def test_require_names_consumer_and_writer():
    # Given a state without walls
    state = example_state(walls=False)
    # When a stage requires wall fields
    with pytest.raises(StateError) as err:
        require(state, ["walls/point", "bodies/x"], consumer="stage cyclic", source="in.h5")
    # Then the message names the file, the consumer, the field and its writer
    msg = str(err.value)
    assert msg.startswith("in.h5: stage cyclic needs walls/point") and "effect walls" in msg
    assert "bodies/x" not in msg


def test_rng_round_trip_continues_stream():
    # Given a generator that has produced some numbers
    gen = np.random.default_rng(7)
    gen.random(5)
    state = State()
    set_rng(state, gen)
    # When it is restored
    restored = get_rng(state)
    # Then both continue with the same numbers
    assert np.array_equal(gen.random(4), restored.random(4))


def test_sphere_centres_rotate_offsets():
    # Given one body rotated 90 degrees about z with a sphere offset along x
    state = example_state(n_bodies=1, spheres_per_body=1)
    state["bodies/x"] = np.array([[1.0, 2.0, 3.0]])
    state["bodies/q"] = np.array([[np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]])
    state["spheres/offset"] = np.array([[0.5, 0.0, 0.0]])
    state["bodies/v"] = np.zeros((1, 3))
    state["bodies/omega"] = np.array([[0.0, 0.0, 2.0]])
    # When the world centre and velocity are computed
    c, v = state.sphere_centres(), state.sphere_velocities()
    # Then the offset points along +y, and the velocity is omega x arm along -x
    assert np.allclose(c, [[1.0, 2.5, 3.0]])
    assert np.allclose(v, [[-1.0, 0.0, 0.0]])
