"""Loading case files (demcli.config.load): lines, YAML errors, overrides, load_case."""

import pytest

from demcli.config.load import apply_overrides, load_case, load_yaml, validate
from demcli.config.schema import Float, Int, List, Section, Str
from demcli.errors import ConfigError

SCHEMA = Section(
    {
        "seed": Int(min=0, default=0),
        "stages": List(
            Section({"name": Str(), "steps": Int(min=1), "mu": Float(min=0, default=0.5)}),
            unique_by="name",
        ),
    }
)

CASE = """\
seed: 1
stages:
  - name: settle
    steps: 10
  - name: shake
    steps: 20
"""


def problems(excinfo):
    return [str(e) for e in excinfo.value.errors]


def test_marks_give_the_line_of_every_key_and_item():
    # Given a case as text
    # When loaded
    data, marks = load_yaml(CASE, "case.yaml")
    # Then data is plain python and marks know each path's line
    assert data["stages"][1] == {"name": "shake", "steps": 20}
    assert marks[("seed",)] == 1
    assert marks[("stages",)] == 2
    assert marks[("stages", 1)] == 5
    assert marks[("stages", 1, "steps")] == 6


def test_yaml_1_2_style_exponents_are_floats():
    # Given numbers written as 1e-5 and 2E3 (strings in plain PyYAML)
    data, _ = load_yaml("dt: 1e-5\nn: 2E3\nname: 1e5.csv\n")
    # Then they load as floats, and a file name stays a string
    assert data == {"dt": 1e-5, "n": 2000.0, "name": "1e5.csv"}


def test_duplicate_keys_are_all_reported_with_both_lines():
    # Given a case with two duplicated keys at different depths
    text = "seed: 1\nstages:\n  - name: a\n    steps: 1\n    steps: 2\nseed: 2\n"
    # When loaded
    with pytest.raises(ConfigError) as info:
        load_yaml(text, "case.yaml")
    # Then both duplicates are errors with the line of each copy
    assert problems(info) == [
        "case.yaml:5: stages[0].steps: duplicate key; first given at line 4",
        "case.yaml:6: seed: duplicate key; first given at line 1",
    ]
    assert info.value.exit_code == 2


def test_merge_keys_are_not_duplicates():
    # Given a mapping that merges an anchor and overrides one of its keys
    text = "base: &b {steps: 5, mu: 0.1}\nstage:\n  <<: *b\n  mu: 0.2\n"
    # When loaded
    data, _ = load_yaml(text)
    # Then the explicit key wins, without a duplicate-key error
    assert data["stage"] == {"steps": 5, "mu": 0.2}


@pytest.mark.parametrize(
    "text, expected",
    [
        ("seed: 1\nstages: [1, 2\nx: 3\n", "case.yaml:3: YAML syntax error: expected ',' or ']'"),
        ("seed: 1\n  steps: 2\n", "case.yaml:2: YAML syntax error: mapping values are not allowed here"),
        ("- 1\n- 2\n", "case.yaml:1: the top level must be a mapping of keys, not a list"),
        ("", "case.yaml:1: the case is empty"),
        ("just text\n", "case.yaml:1: the top level must be a mapping of keys, not a single value ('just text')"),
    ],
)
def test_not_a_case_mapping_is_a_config_error_with_line(text, expected):
    # Given text that is not YAML, or not a mapping
    # When loaded
    with pytest.raises(ConfigError) as info:
        load_yaml(text, "case.yaml")
    # Then the one error names file and line
    assert len(info.value.errors) == 1
    assert str(info.value.errors[0]).startswith(expected)


def test_missing_file_names_the_path(tmp_path):
    # Given a path that does not exist
    path = tmp_path / "nope.yaml"
    # When loaded
    with pytest.raises(ConfigError) as info:
        load_yaml(path)
    # Then the error names the path
    assert problems(info) == [f"{path}: file not found"]


def test_overrides_by_name_index_and_key():
    # Given a loaded case
    data, marks = load_yaml(CASE, "case.yaml")
    # When overridden by item name, by index and by top-level key
    new, new_marks = apply_overrides(data, marks, ["stages.settle.steps=100", "stages.1.mu=0.25", "seed=3"])
    node = validate(new, new_marks, SCHEMA, "case.yaml")
    # Then the values change, parsed as YAML, and the input is untouched
    assert (node.seed, node.stages[0].steps, node.stages[1].mu) == (3, 100, 0.25)
    assert data["stages"][0]["steps"] == 10
    # And lines of untouched values are kept, overridden ones are labelled
    assert new_marks[("stages", 1, "steps")] == 6
    assert new_marks[("stages", 0, "steps")] == "--set stages.settle.steps=100"


def test_invalid_override_value_is_reported_against_the_override():
    # Given an override that sets an out-of-range value and one with a misspelt key
    data, marks = load_yaml(CASE, "case.yaml")
    new, new_marks = apply_overrides(data, marks, ["stages.shake.steps=0", "stages.0.stpes=3"])
    # When validated
    with pytest.raises(ConfigError) as info:
        validate(new, new_marks, SCHEMA, "case.yaml")
    # Then each issue names the override instead of a file line
    assert problems(info) == [
        "--set stages.0.stpes=3: stages[0].stpes: unknown key; did you mean 'steps'?",
        "--set stages.shake.steps=0: stages[1].steps: must be >= 1 (got 0)",
    ]


def test_overrides_that_cannot_apply_fail_at_once_naming_each_override():
    # Given a loaded case and overrides into a missing item, past the list, through a
    # plain value, and malformed
    data, marks = load_yaml(CASE, "case.yaml")
    bad = ["stages.compact.steps=5", "stages.7.steps=1", "seed.x=1", "seed", "seed=[1"]
    # When applied
    with pytest.raises(ConfigError) as info:
        apply_overrides(data, marks, bad)
    # Then every override is reported by its own text
    msgs = problems(info)
    assert msgs[0] == ("--set stages.compact.steps=5: stages has no item named 'compact' "
                       "(names: 'settle', 'shake')")
    assert msgs[1] == "--set stages.7.steps=1: stages has 2 items; no index 7"
    assert msgs[2] == "--set seed.x=1: seed is a single value (1), so it has no 'x'"
    assert msgs[3].startswith("--set seed: an override must read path=value")
    assert msgs[4].startswith("--set seed=[1: the value is not valid YAML")


def test_override_creates_missing_mapping_keys():
    # Given a case without seed
    data, marks = load_yaml("stages: []\n")
    # When seed is set by override
    new, _ = apply_overrides(data, marks, ["seed=9"])
    # Then it is added
    assert new == {"stages": [], "seed": 9}


def test_load_case_reads_overrides_and_validates(tmp_path):
    # Given a case file on disk
    path = tmp_path / "case.yaml"
    path.write_text(CASE.replace("steps: 20", "steps: -20"))
    # When loaded without overrides, the error names the file and line
    with pytest.raises(ConfigError) as info:
        load_case(path, SCHEMA)
    assert problems(info) == [f"{path}:6: stages[1].steps: must be >= 1 (got -20)"]
    # And an override can fix it
    node = load_case(path, SCHEMA, overrides=["stages.shake.steps=20"])
    assert node.stages[1].steps == 20
    assert node.stages[0].line_of("steps") == 4


def test_case_reference_doc_is_current():
    # Given the schema-generated case reference
    from pathlib import Path

    from demcli.config.docs import cases_markdown
    from demcli.stages.base import case_schema

    doc = Path(__file__).resolve().parents[2] / "docs" / "cases.md"
    # Then docs/cases.md matches it (regenerate with demcli.stages.base.write_cases_doc())
    assert doc.read_text() == cases_markdown(case_schema())
