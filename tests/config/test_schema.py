"""The schema language (demcli.config.schema): rules, error collection, nodes, hashing."""

import pickle

import pytest

from demcli.config.load import load_yaml
from demcli.config.schema import (
    Bool,
    ConfigIssue,
    Float,
    Int,
    List,
    Map,
    Node,
    Optional,
    SchemaError,
    Section,
    Str,
    Tagged,
    Vector,
    canonical_json,
    format_path,
    sha256_of,
    validate_tree,
)


def check_voids(node, report):
    if node.e_min >= node.e_max:
        report("e_min", "must be < e_max", node.e_min)


MATERIAL = Section(
    {
        "density": Float("kg/m^3", min=0, min_inclusive=False, doc="solid density"),
        "e_min": Float(min=0, default=0.3),
        "e_max": Float(min=0, default=0.9),
    },
    check=check_voids,
)
STAGE = Section(
    {
        "name": Str(pattern=r"[a-z_]+"),
        "steps": Int(min=1),
        "dt": Float("s", min=0, min_inclusive=False, default="1 us"),
        "physics": Section(
            {
                "friction": Optional(Section({"mu": Float(min=0), "k_t": Float("N/m", min=0, default=0.0)})),
                "gravity": Vector(3, "m/s^2", default=[0, 0, -9.81]),
            },
            default={},
        ),
    }
)
SCHEMA = Section(
    {
        "seed": Int(min=0, default=0),
        "verbose": Bool(default=False),
        "mode": Str(choices=["fast", "exact"], default="fast"),
        "box": Vector(3, "m", min=0, default="0.6 0.3 0.35 m"),
        "materials": Map(MATERIAL, key_pattern=r"[A-Za-z_]\w*"),
        "contact": Tagged(
            "type",
            {"hertz": {"E": Float("Pa", min=0, min_inclusive=False)}, "hooke": {"k_n": Float("N/m", min=0)}},
        ),
        "stages": List(STAGE, min_len=1, unique_by="name"),
    }
)

GOOD = """\
seed: 3
materials:
  granite:
    density: 2.6 g/cm3
contact:
  type: hertz
  E: 40 GPa
stages:
  - name: settle
    steps: 100
  - name: shake
    steps: 1e3
    dt: 2 us
    physics:
      friction: {mu: 0.3}
"""


def run(text, schema=SCHEMA):
    data, marks = load_yaml(text, "case.yaml")
    return validate_tree(schema, data, marks, "case.yaml")


def messages(text, schema=SCHEMA):
    node, issues = run(text, schema)
    assert node is None
    return [str(i) for i in issues]


def test_valid_case_becomes_read_only_nodes_in_si():
    # Given a valid case with units and omitted defaults
    node, issues = run(GOOD)
    # Then there are no issues and values are SI floats, defaults filled in
    assert issues == []
    assert node.materials.granite.density == pytest.approx(2600.0)
    assert node.materials["granite"].e_max == 0.9
    assert node.contact.type == "hertz" and node.contact.E == 4e10
    assert node.stages[1].steps == 1000 and isinstance(node.stages[1].steps, int)
    assert node.stages[0].dt == pytest.approx(1e-6)
    assert node.stages[0].physics.friction is None
    assert node.stages[1].physics.friction.k_t == 0.0
    assert node.box == (0.6, 0.3, 0.35)
    assert node.stages[1].physics.gravity == (0.0, 0.0, -9.81)
    assert isinstance(node.stages, tuple)
    # And the nodes are read-only, know their path and their lines
    with pytest.raises(AttributeError, match="read-only"):
        node.seed = 4
    with pytest.raises(AttributeError, match="no key 'sede'"):
        node.sede
    assert node.stages[1].physics.path == "stages[1].physics"
    assert node.stages[1].line_of("steps") == 12
    assert node.stages[0].line_of("dt") is None  # a default


def test_to_dict_gives_plain_python_and_nodes_pickle():
    # Given a validated case
    node, _ = run(GOOD)
    # When converted to plain data
    plain = node.to_dict()
    # Then nested nodes are dicts and tuples are lists
    assert type(plain["stages"]) is list and type(plain["stages"][1]["physics"]) is dict
    assert plain["box"] == [0.6, 0.3, 0.35]
    # And nodes are hashable and survive pickling (for worker processes)
    assert hash(node) == hash(pickle.loads(pickle.dumps(node)))
    assert pickle.loads(pickle.dumps(node)) == node


@pytest.mark.parametrize(
    "field, value, rule",
    [
        (Float(min=0), -0.2, "must be >= 0 (got -0.2)"),
        (Float(min=0, min_inclusive=False), 0, "must be > 0 (got 0)"),
        (Float(min=0, max=1, min_inclusive=False), 1.5, "must be in (0, 1] (got 1.5)"),
        (Float("m", max="10 mm", max_inclusive=False), "2 cm", "must be < 0.01 m (got 2 cm = 0.02 m)"),
        (Float("m"), "3 kg", '"3 kg" has unit kilogram, which is not a length (expected m)'),
        (Float(), "abc", 'cannot parse "abc"'),
        (Float(), True, "must be a number (got true)"),
        (Float(), [1], "must be a number (got [1])"),
        (Float(), float("nan"), "must be a finite number"),
        (Int(min=1), 0, "must be >= 1 (got 0)"),
        (Int(max=5), 6, "must be <= 5 (got 6)"),
        (Int(), True, "must be an integer (got true)"),
        (Int(), 1.5, "must be an integer (got 1.5)"),
        (Int(), "3", "must be an integer (got '3')"),
        (Bool(), 1, "must be true or false (got 1)"),
        (Str(), 3, "must be a string (got 3)"),
        (Str(choices=["hertz", "hooke"]), "hetz", "must be one of 'hertz', 'hooke' (got 'hetz'); did you mean 'hertz'?"),
        (Str(pattern=r"[a-z]+"), "Settle", "must match '[a-z]+' (got 'Settle')"),
        (Vector(3, "m"), [1, 2], "must have 3 components, not 2"),
        (Vector(2, "m"), 5, "must be a list of 2 numbers (got 5)"),
        (List(Int(), min_len=1), [], "must not be empty, has 0"),
        (List(Int(), max_len=1), [1, 2], "must have at most 1 items, has 2"),
        (List(Int()), {"a": 1}, "must be a list"),
        (Map(Int(), key_pattern=r"[a-z]+"), {"Bad": 1}, "key must match '[a-z]+' (got 'Bad')"),
        (Section({"a": Int()}), [1], "must be a mapping of keys (got [1])"),
    ],
)
def test_each_rule_reports_path_rule_and_value(field, value, rule):
    # Given a field and a value that breaks one of its rules
    # When validated at path x
    node, issues = validate_tree(Section({"x": field}), {"x": value}, {("x",): 7}, "case.yaml")
    # Then exactly one issue names the file, line, path, rule and value
    assert node is None
    assert len(issues) == 1
    assert str(issues[0]).startswith("case.yaml:7: x")
    assert rule in str(issues[0])


def test_unknown_key_gets_did_you_mean_and_missing_key_points_at_parent():
    # Given a section with a misspelt key and a missing required one
    text = "stages:\n  - name: a\n    steps: 1\n    physics:\n      frictoin: {mu: 0.3}\n"
    # When validated
    msgs = messages(text)
    # Then the misspelling gets a hint, and missing keys point at the parent's line
    assert "case.yaml:5: stages[0].physics.frictoin: unknown key; did you mean 'friction'?" in msgs
    assert "case.yaml:1: materials: required key is missing" in msgs
    assert "case.yaml:1: contact: required key is missing" in msgs


def test_unknown_key_without_close_match_lists_the_known_keys():
    # Given a key that resembles nothing
    _, issues = validate_tree(Section({"alpha": Int(default=1)}), {"zzz": 1})
    # Then the hint lists what is allowed
    assert str(issues[0]) == "zzz: unknown key; expected one of 'alpha'"


def test_tagged_unknown_type_gets_did_you_mean_and_variant_keys_are_checked():
    # Given a tagged section with a misspelt type, then a valid type with a foreign key
    base = "materials: {}\nstages: [{name: a, steps: 1}]\n"
    # When validated
    bad_type = messages(base + "contact:\n  type: hertx\n  E: 1 GPa\n")
    foreign = messages(base + "contact:\n  type: hooke\n  E: 1 GPa\n")
    missing = messages(base + "contact: {E: 1}\n")
    # Then each gets a precise message
    assert bad_type == ["case.yaml:4: contact.type: unknown type (got 'hertx'); did you mean 'hertz'?"]
    assert "case.yaml:5: contact.E: unknown key; expected one of 'k_n'" in foreign
    assert "case.yaml:3: contact.k_n: required key is missing" in foreign
    assert missing == ["case.yaml:3: contact.type: required key is missing; one of 'hertz', 'hooke'"]


def test_all_errors_are_reported_at_once_with_lines_in_file_order():
    # Given a case with eight distinct mistakes spread over the file, not in schema order
    text = """\
seed: -1
verbose: 1
materials:
  granite:
    density: 2.6 g/cm3
    e_min: 0.95
  basalt:
    density: -3
contact:
  type: hertz
  E: 40 GPa
stages:
  - name: settle
    steps: 0
  - name: shake
    steps: 10
    physics:
      friction:
        mu: -0.2
      gravity: [0, 0, 9.81 kg]
mode: fsat
"""
    # When validated
    msgs = messages(text)
    # Then every one is reported, each with its own line, in file order
    assert msgs == [
        "case.yaml:1: seed: must be >= 0 (got -1)",
        "case.yaml:2: verbose: must be true or false (got 1)",
        "case.yaml:6: materials.granite.e_min: must be < e_max (got 0.95)",
        "case.yaml:8: materials.basalt.density: must be > 0 kg/m^3 (got -3)",
        "case.yaml:14: stages[0].steps: must be >= 1 (got 0)",
        "case.yaml:19: stages[1].physics.friction.mu: must be >= 0 (got -0.2)",
        'case.yaml:20: stages[1].physics.gravity[2]: "9.81 kg" has unit kilogram, '
        "which is not an acceleration (expected m/s^2)",
        "case.yaml:21: mode: must be one of 'fast', 'exact' (got 'fsat'); did you mean 'fast'?",
    ]


def test_cross_field_check_runs_only_when_fields_are_valid():
    # Given a section whose check would fail, but one of whose fields is invalid
    calls = []

    def check(node, report):
        calls.append(node)
        report("", "never reached")

    schema = Section({"a": Int(min=0), "b": Int()}, check=check)
    # When validated with a bad field
    _, issues = validate_tree(schema, {"a": -1, "b": 2})
    # Then only the field error is reported and the check did not run
    assert [i.path for i in issues] == ["a"]
    assert calls == []
    # And with valid fields the check runs and can report on the section itself
    _, issues = validate_tree(schema, {"a": 1, "b": 2})
    assert [str(i) for i in issues] == ["never reached"]


def test_unique_by_names_the_first_use():
    # Given two stages with the same name
    text = GOOD.replace("name: shake", "name: settle")
    # When validated
    msgs = messages(text)
    # Then the duplicate is reported with the first item's path
    assert msgs == ["case.yaml:11: stages[1].name: duplicate name (got 'settle'); already used by stages[0]"]


def test_vector_forms():
    # Given vectors as a unit string, as a list of quantities and as plain numbers
    field = Section({"v": Vector(3, "m", min=0)})
    # When validated
    a, _ = validate_tree(field, {"v": "600, 300, 350 mm"})
    b, _ = validate_tree(field, {"v": ["60 cm", 0.3, "35 cm"]})
    _, issues = validate_tree(field, {"v": [1, -2, 3]})
    # Then all convert to SI tuples and component errors name the index
    assert a.v == pytest.approx((0.6, 0.3, 0.35)) and b.v == pytest.approx((0.6, 0.3, 0.35))
    assert [str(i) for i in issues] == ["v[1]: must be >= 0 m (got -2)"]


def test_empty_yaml_values_mean_empty_sections_lists_and_maps():
    # Given keys present but empty (YAML null)
    schema = Section({"s": Section({"a": Int(default=1)}), "l": List(Int()), "m": Map(Int()),
                      "o": Optional(Int())})
    # When validated
    node, issues = validate_tree(schema, {"s": None, "l": None, "m": None, "o": None})
    # Then defaults apply, lists are empty tuples, maps empty nodes, optionals None
    assert issues == []
    assert node.s.a == 1 and node.l == () and dict(node.m) == {} and node.o is None


def test_schema_mistakes_are_caught_early():
    # Given schema definitions with reserved field names or bad defaults
    # Then they raise SchemaError at definition or first use
    with pytest.raises(SchemaError, match="reserved"):
        Section({"path": Str()})
    with pytest.raises(SchemaError, match="tag key"):
        Tagged("type", {"a": Section({"type": Str()})})
    with pytest.raises(SchemaError, match="invalid default"):
        validate_tree(Section({"x": Float("m", default="3 kg")}), {})


def test_canonical_json_is_stable_under_key_order_and_exact_for_floats():
    # Given the same case with keys in a different order
    node_a, _ = run(GOOD)
    reordered = """\
stages:
  - steps: 100
    name: settle
  - physics:
      friction: {mu: 0.3}
    dt: 2 us
    steps: 1e3
    name: shake
contact: {E: 40 GPa, type: hertz}
materials: {granite: {density: 2.6 g/cm3}}
seed: 3
"""
    node_b, _ = run(reordered)
    # When hashed
    # Then the canonical text and hash are equal
    assert canonical_json(node_a) == canonical_json(node_b)
    assert sha256_of(node_a) == sha256_of(node_b)
    # And changing a value changes the hash; floats are written exactly
    node_c, _ = run(GOOD.replace("seed: 3", "seed: 4"))
    assert sha256_of(node_c) != sha256_of(node_a)
    assert canonical_json({"b": 0.1 + 0.2, "a": (1, None)}) == '{"a":[1,null],"b":0.30000000000000004}'
    with pytest.raises(ValueError):
        canonical_json({"x": float("inf")})


def test_doc_table_lists_every_field_with_type_unit_default_and_doc():
    # Given the schema
    # When its doc table is produced
    rows = {r.path: r for r in SCHEMA.doc_table()}
    # Then nested fields appear with their units, defaults and docs
    density = rows["materials.<name>.density"]
    assert (density.type, density.unit, density.default, density.doc) == ("float > 0", "kg/m^3", "required", "solid density")
    assert rows["stages[].dt"].default == "1 us"
    assert rows["stages[].physics.friction"].type == "optional section"
    assert rows["contact[type=hooke].k_n"].unit == "N/m"
    assert rows["mode"].type == "one of fast|exact"


def test_issue_and_path_formatting():
    # Given issue parts
    issue = ConfigIssue("case.yaml", 14, "stages[2].physics.friction.mu", "must be >= 0", -0.2)
    # Then the message reads file:line: path: rule (got value)
    assert str(issue) == "case.yaml:14: stages[2].physics.friction.mu: must be >= 0 (got -0.2)"
    assert format_path(("stages", 2, "physics")) == "stages[2].physics"
    assert format_path(("materials", "granite A")) == "materials['granite A']"
    assert isinstance(Node({"a": 1}), Node)
