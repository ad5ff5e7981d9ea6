"""Issue 27: inputs that lost data or crashed, and what a newcomer trips over. Each is now one
clear error (file, line, key, rule, value), exit code 2, no traceback, before anything runs."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from demcli.cli import cli
from demcli.config.load import MAX_CASE_BYTES, apply_overrides, load_yaml
from demcli.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
CASES = ROOT / "cases"

GOOD = """\
name: tiny
seed: 1
materials: {glass: {density: 2500 kg/m^3, young: 50 MPa}}
stages:
  - {name: pour, type: generate, region: {shape: box, min: [0, 0, 0], max: [10 mm, 10 mm, 10 mm]}, count: 5,
     radius: {min: 1 mm, max: 1 mm}, material: glass}
  - name: settle
    type: dem
    physics: {gravity: [0, 0, -9.81], friction: true}
    walls: [{type: box, name: bin, min: [0, 0, 0], max: [10 mm, 10 mm, 10 mm], material: glass}]
    time: {steps: 10}
"""

BOMB = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{c}: &{c} [" + ", ".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefgh", "bcdefghi"))


def _check(tmp_path, text, name="case.yaml", *args):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return CliRunner().invoke(cli, ["check", str(path), *args]), path


def _refused(result, *needles):
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output and "Error" in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)
    return result.output


def _problems(excinfo):
    return [str(e) for e in excinfo.value.errors]


# ---------------------------------------------------------------------------------------
# 4. alias bombs and oversized documents
# ---------------------------------------------------------------------------------------

def test_an_alias_bomb_is_refused_at_once_with_file_and_line(monkeypatch):
    import yaml

    # Given a 1.4 kB "billion laughs" document (9^9 values once expanded)
    text = BOMB + "stages: []\n"
    assert len(text) < 1500
    # When loaded, with any construction of Python values from its nodes made to fail loudly
    def build(*args, **kwargs):
        raise AssertionError("the bomb's values were being built")

    monkeypatch.setattr(yaml.constructor.BaseConstructor, "construct_object", build)
    with pytest.raises(ConfigError) as info:
        load_yaml(text, "bomb.yaml")
    # Then it is refused before any value is built, at the line where the expansion outgrows the bound
    (msg,) = _problems(info)
    assert msg.startswith("bomb.yaml:6: this value expands to more than 100000 values"), msg


def test_an_alias_bomb_through_the_cli_is_exit_code_2(tmp_path):
    result, path = _check(tmp_path, BOMB + GOOD, "bomb.yaml")
    _refused(result, f"{path}:", "alias bomb")


def test_aliases_a_case_uses_still_load():
    # Given anchors used a few times, merged and nested
    data, _ = load_yaml("base: &b {mu: 0.3, k: [1, 2]}\nx: *b\ny: {<<: *b, mu: 0.4}\nz: [*b, *b]\n")
    # Then they expand as before
    assert data["z"][1] == {"mu": 0.3, "k": [1, 2]} and data["y"]["mu"] == 0.4


def test_a_file_over_the_size_bound_is_refused_unread(tmp_path):
    # Given a case file of more than MAX_CASE_BYTES
    result, path = _check(tmp_path, GOOD + "#" * (MAX_CASE_BYTES + 10) + "\n", "huge.yaml")
    # Then its size is the error
    _refused(result, f"{path}: larger than {MAX_CASE_BYTES} bytes")


def test_nesting_deeper_than_the_reader_can_follow_is_an_error():
    with pytest.raises(ConfigError) as info:
        load_yaml("a: 1\nb: " + "[" * 600 + "]" * 600 + "\n", "deep.yaml")
    assert _problems(info) == ["deep.yaml:2: nested too deeply to read"]


# ---------------------------------------------------------------------------------------
# 5. control characters and NUL
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("char, line, column", [("\x00", 2, 8), ("\x07", 4, 3), ("\x1b", 1, 1)])
def test_a_control_character_names_file_line_and_character(char, line, column):
    # Given a case with a control character at a known place
    lines = GOOD.splitlines(keepends=True)
    lines[line - 1] = lines[line - 1][:column - 1] + char + lines[line - 1][column - 1:]
    # When loaded
    with pytest.raises(ConfigError) as info:
        load_yaml("".join(lines), "case.yaml")
    # Then one issue names the file, line, the character and its column
    (msg,) = _problems(info)
    assert msg == (f"case.yaml:{line}: control character U+{ord(char):04X} is not allowed in YAML; delete it (in a "
                   f"double-quoted string it may be written as an escape) (got {char!r}); column {column}")


def test_a_nul_byte_in_a_file_is_exit_code_2(tmp_path):
    result, path = _check(tmp_path, GOOD.encode().replace(b"seed: 1", b"seed: 1\x00"), "nul.yaml")
    _refused(result, f"{path}:2:", "U+0000")


def test_a_control_character_in_an_override_value_names_the_override():
    data, marks = load_yaml(GOOD, "case.yaml")
    with pytest.raises(ConfigError) as info:
        apply_overrides(data, marks, ["seed=1\x07"])
    assert _problems(info)[0].startswith("--set seed=1\x07: the value is not valid YAML: control character U+0007")


# ---------------------------------------------------------------------------------------
# 6. seeds beyond what a state file stores
# ---------------------------------------------------------------------------------------

def test_a_seed_beyond_64_bits_is_refused_at_check(tmp_path):
    result, path = _check(tmp_path, GOOD.replace("seed: 1", "seed: 1180591620717411303424"))
    _refused(result, f"{path}:2: seed: must be <= 9223372036854775807 (got 1180591620717411303424)")


def test_the_seed_bound_is_what_a_state_file_holds(tmp_path):
    from demcli.config.case import SEED_MAX
    from demcli.state import read_meta, write_state
    from demcli.state.fields import example_state

    # Given a state with the largest accepted seed, and one with the next
    st = example_state()
    st.meta["seed"] = SEED_MAX
    write_state(tmp_path / "max.h5", st)
    assert read_meta(tmp_path / "max.h5")["seed"] == SEED_MAX
    st.meta["seed"] = SEED_MAX + 1
    with pytest.raises(OverflowError):
        write_state(tmp_path / "over.h5", st)
    # And the case accepts the first
    result, _ = _check(tmp_path, GOOD.replace("seed: 1", f"seed: {SEED_MAX}"))
    assert result.exit_code == 0, result.output


def test_a_library_seed_is_bounded_as_the_case_seed(tmp_path):
    text = (CASES / "quickstart.yaml").read_text().replace("seed: 2017\n  - name: assembly", f"seed: {2 ** 64}\n  - name: assembly")
    result, path = _check(tmp_path, text, "q.yaml")
    _refused(result, "stages[1].seed: must be <= 9223372036854775807")


# ---------------------------------------------------------------------------------------
# 7. scenes larger than the machine's memory
# ---------------------------------------------------------------------------------------

def test_the_machine_memory_is_known():
    import os

    from demcli.config.memory import machine_memory

    mem = machine_memory()
    assert 0 < mem <= os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def test_a_count_beyond_memory_is_refused_with_the_estimate_and_the_machines_figure(tmp_path, monkeypatch):
    from demcli.config import memory

    # Given a machine of 8 GiB and a generate stage of 1e8 spheres
    monkeypatch.setattr(memory, "machine_memory", lambda: 8 * 2 ** 30)
    result, path = _check(tmp_path, GOOD.replace("count: 5", "count: 100000000"))
    # Then check refuses it, naming the estimate and the machine's memory
    _refused(result, f"{path}:5: stages[0].count: the generated particles: about 1e+08 spheres need an estimated "
                     "286 GiB of memory (3072 bytes each), more than this machine's 8 GiB (got 100000000)")


def test_every_stage_that_makes_particles_is_bounded(tmp_path, monkeypatch):
    from demcli.config import memory

    # Given a machine of 1 kB, the smoke cases that count, lattice and tile particles
    monkeypatch.setattr(memory, "machine_memory", lambda: 1024)
    expected = {"smoke/beads.yaml": ["stages[0].count"],
                "smoke/clumps.yaml": ["stages[0].count"],
                "smoke/sand_asphalt_uniaxial.yaml": ["stages[0].count"],
                "smoke/asphalt_carved_cube.yaml": ["stages[2].lattice.spacing", "stages[5].ball_radius"],
                "smoke/marshall_2d.yaml": ["stages[2].ball_radius"],
                "quickstart.yaml": ["stages[1].per_class"],
                "smoke/ballast_clumps.yaml": ["stages[1].per_class", "stages[3].balls.relative"]}
    for case, keys in expected.items():
        result = CliRunner().invoke(cli, ["check", str(CASES / case)])
        # Then each stage's count is refused, and nothing else
        out = _refused(result, *keys)
        assert out.count("more than this machine's") == len(keys), out


# ---------------------------------------------------------------------------------------
# 10. what run rejected after earlier stages ran
# ---------------------------------------------------------------------------------------

def test_a_box_wall_with_max_below_min_is_refused(tmp_path):
    result, path = _check(tmp_path, GOOD.replace("max: [10 mm, 10 mm, 10 mm], material", "max: [10 mm, -1 mm, 10 mm], "
                                                                                         "material"))
    _refused(result, f"{path}:10: stages[1].walls[0].max[1]: must be > min (0 m) (got -0.001)")


def test_a_stage_whose_input_no_earlier_stage_writes_is_refused(tmp_path):
    # Given a compact stage right after generate
    text = GOOD.replace("type: dem", "type: compact").replace("material: glass}]", "material: glass}]\n"
                                                              "    target: {porosity: 0.4}")
    result, path = _check(tmp_path, text)
    # Then check names the missing field, the stage before, and who writes it
    _refused(result, f"{path}:8: stages[1].type: stage type compact needs aggregates/volume in its input, which no "
                     "earlier stage writes (the input is the output of stage 'pour', type generate); stage types "
                     "that write it: carve, cut")


def test_a_first_stage_that_needs_an_input_is_refused(tmp_path):
    head, stages = GOOD.split("stages:\n")
    pour, settle = stages.split("  - name: settle")
    result, path = _check(tmp_path, head + "stages:\n  - name: settle" + settle + pour)
    _refused(result, f"{path}:6: stages[0].type: stage type dem reads the state of an earlier stage, but this is the "
                     "first stage; start with a stage that makes a scene (generate, gradation, particles, prepare)")


def test_what_a_config_reads_besides_its_type_must_be_written_before(tmp_path):
    # Given a dem stage taking bond models from a phase table nobody wrote
    text = GOOD.replace("time: {steps: 10}", "time: {steps: 10}\n    contact: {law: linear, kn: 1e4}\n"
                                             "    bonds: {from_phases: true}")
    result, _ = _check(tmp_path, text)
    _refused(result, "stages[1].bonds.from_phases: reads phases/sphere, phases/pair_model from the input",
             "stage types that write it: mastic")


def test_a_library_too_small_for_the_gradation_is_refused(tmp_path):
    # Given the quickstart with one particle per class
    text = (CASES / "quickstart.yaml").read_text().replace("per_class: 120", "per_class: 1")
    result, path = _check(tmp_path, text, "q.yaml")
    # Then check refuses it at per_class, with the class, its volume and the least per_class
    _refused(result, "stages[1].per_class: class 35.5-45 mm of stage 'grading' needs 1727 cm^3 of ballast, more than 1 "
                     "particles of at most 234 cm^3 can hold (got 1); raise per_class to at least 8")
    # and the shipped per_class passes
    assert CliRunner().invoke(cli, ["check", str(CASES / "quickstart.yaml")]).exit_code == 0


def test_a_gradation_class_no_library_covers_is_refused(tmp_path):
    text = (CASES / "quickstart.yaml").read_text().replace("passing: [0,     0,     4,", "passing: [10,    10,    14,")
    result, _ = _check(tmp_path, text, "q.yaml")
    _refused(result, "stages[2]: size class 0-16 mm of stage 'grading' holds 10 % of the mass but a library has no "
                     "particles for it")


@pytest.mark.parametrize("wall, needle", [
    ("{type: box, min: [0, 0, 0], max: [1, 1, 1], material: glass, motion: {z1: {mode: pressure, pressure: 1, "
     "mass: 1}}}", "walls[1].motion.z1.mode: mode pressure is for cylinder walls"),
    ("{type: cylinder, base: [0, 0, 0], radius: 1, height: 1, material: glass, motion: {mode: servo, stress: 1}}",
     "walls[1].motion.mode: a cylinder wall takes fixed, velocity or pressure"),
    ("{type: plane, point: [0, 0, 1], normal: [0, 0, -1], material: glass, motion: {mode: servo, stress: 1}}",
     "walls[1].motion.area: a servo plane needs its loaded area"),
])
def test_wall_modes_a_wall_cannot_take_are_refused(tmp_path, wall, needle):
    text = GOOD.replace("material: glass}]", f"material: glass}}, {wall}]")
    _refused(_check(tmp_path, text)[0], needle)


def test_stages_that_need_another_dimension_are_refused(tmp_path):
    text = (CASES / "smoke" / "marshall_2d.yaml").read_text().replace("dimension: 2", "dimension: 3")
    result, _ = _check(tmp_path, text, "m.yaml")
    _refused(result, "stages[0].specimen: a rectangle specimen is 2D but the case has dimension 3",
             "stages[1]: a polygons section is 2D; set dimension: 2", "stages[2]: a discretized section is 2D")


def test_physics_the_scene_cannot_take_is_refused(tmp_path):
    # (the effect registry's shape support, demcli.effects: rolling resistance is not for polyhedra)
    text = (CASES / "quickstart.yaml").read_text().replace("contact_damping: true", "contact_damping: true\n"
                                                           "      rolling_resistance: true")
    result, _ = _check(tmp_path, text, "q.yaml")
    _refused(result, "stages[3].physics.rolling_resistance: is not for polyhedra: a rolling-resistance moment "
             "corrects spheres for the shape they lack")


def test_a_linearized_geometry_is_refused_on_spheres(tmp_path):
    # (contact.geometry_refresh linearizes the intersection of polyhedron pairs; spheres have none)
    text = GOOD.replace("time: {steps: 10}", "time: {steps: 10}\n    contact: {geometry_refresh: 4}")
    _refused(_check(tmp_path, text)[0], "stages[1].contact.geometry_refresh: is for polyhedron scenes")


def test_run_refuses_before_the_first_stage_runs(tmp_path):
    # Given a valid first stage and a second whose input it cannot provide
    path = tmp_path / "case.yaml"
    path.write_text(GOOD.replace("type: dem", "type: compact").replace(
        "material: glass}]", "material: glass}]\n    target: {porosity: 0.4}"))
    # When run
    result = CliRunner().invoke(cli, ["run", str(path), "--out", str(tmp_path / "run"), "--quiet"])
    # Then it is refused and nothing ran: not even the generate stage's state exists
    _refused(result, "stage type compact needs aggregates/volume")
    assert not (tmp_path / "run").exists()


def test_every_required_field_is_written_by_some_stage_type():
    from demcli.stages.base import load_stage_types, writers_of

    types = load_stage_types()
    for name, st in types.items():
        assert st.provides, f"{name} declares no outputs"
        for path in st.requires:
            assert writers_of(path), f"{name} requires {path}, which no stage type writes"


def test_scenes_follow_what_stages_write_and_keep():
    from demcli.stages.base import has_field, input_scenes, load_case

    case = load_case(CASES / "quickstart.yaml")
    scenes = input_scenes(case.stages)
    # Then the first stage has no input, the library keeps the gradation and the deposit gets both
    assert scenes[0] is None
    assert has_field(scenes[2], "gradation/class_count") and has_field(scenes[2], "library/path")
    assert has_field(scenes[3], "polyhedra/shape") and has_field(scenes[5], "library/generator")


# ---------------------------------------------------------------------------------------
# 11. one pass
# ---------------------------------------------------------------------------------------

def test_an_unknown_material_is_reported_with_the_other_errors(tmp_path):
    # Given a misspelt material, a bad step count and a stage out of order
    text = GOOD.replace("material: glass}\n  - name", "material: glas}\n  - name").replace("steps: 10", "steps: -1")
    text = text.replace("  - {name: pour", "  - {name: mould, type: dem, time: {steps: 1}}\n  - {name: pour")
    result, path = _check(tmp_path, text)
    # Then all three come in one report
    out = _refused(result, "invalid case (3 problems)", "stages[0].type: stage type dem reads the state",
                   "stages[1].material: unknown material 'glas'; did you mean 'glass'?",
                   "stages[2].time.steps: must be >= 1 (got -1)")
    assert out.index("stages[0]") < out.index("stages[1]") < out.index("stages[2]")


def test_a_case_rule_of_a_valid_stage_comes_with_a_typo_in_a_later_one(tmp_path, monkeypatch):
    """The case rules (memory, scene, library fit) ran only once every field was valid: a
    typo in the dem stage hid the memory refusal of the generate stage before it."""
    from demcli.config import memory

    monkeypatch.setattr(memory, "machine_memory", lambda: 8 * 2 ** 30)
    text = GOOD.replace("count: 5", "count: 100000000").replace("time: {steps: 10}", "time: {stepz: 10}")
    result, path = _check(tmp_path, text)
    _refused(result, "invalid case (2 problems)", f"{path}:5: stages[0].count: the generated particles",
             "stages[1].time.stepz: unknown key; did you mean 'steps'?")


def test_unknown_materials_in_lists_and_named_keys_are_reported(tmp_path):
    text = GOOD.replace("time: {steps: 10}", "time: {steps: 10}\n    contact: {pairs: [{materials: [glass, stel], "
                                             "friction: 0.1}]}")
    _refused(_check(tmp_path, text)[0], "stages[1].contact.pairs[0].materials[1]: unknown material 'stel'")


# ---------------------------------------------------------------------------------------
# 15. --set paths, and compare -y
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("path", ["stages.settle.walls[0].max", "stages.settle.walls.0.max",
                                  "stages.settle.walls.bin.max", "stages[settle].walls[bin].max",
                                  "stages[1].walls[0].max", "stages['settle'].walls[\"bin\"].max"])
def test_an_override_reaches_a_list_item_by_bracket_index_or_name(path):
    data, marks = load_yaml(GOOD, "case.yaml")
    new, _ = apply_overrides(data, marks, [f"{path}=[2, 2, 2]"])
    assert new["stages"][1]["walls"][0]["max"] == [2, 2, 2]


@pytest.mark.parametrize("path, rule", [
    ("stages.settle.walls[0.max", "unbalanced brackets"),
    ("stages.settle.walls]0.max", "unbalanced brackets"),
    ("stages.settle.walls[0]max", "a '.' must come before 'max'"),
    ("stages..settle", "empty segment"),
    ("stages.settle.walls[]", "empty segment"),
    ("stages.settle.walls[3].max", "stages[1].walls has 1 items; no index 3"),
])
def test_a_malformed_override_path_names_the_override(path, rule):
    data, marks = load_yaml(GOOD, "case.yaml")
    with pytest.raises(ConfigError) as info:
        apply_overrides(data, marks, [f"{path}=1"])
    (msg,) = _problems(info)
    assert msg.startswith(f"--set {path}=1: ") and rule in msg, msg


def test_the_override_forms_are_documented():
    readme = (ROOT / "README.md").read_text()
    for form in ("stages.settle.walls[1].max", "stages.settle.walls.1.max", "stages.settle.walls.lid.max"):
        assert form in readme
    for command in ("run", "check"):
        text = " ".join(CliRunner().invoke(cli, [command, "--help"]).output.split())
        assert "walls[1].max" in text and "walls.1.max" in text and "walls.lid.max" in text, text


def test_compare_takes_a_comma_list_of_columns(tmp_path):
    # Given a run folder with one record table
    run = tmp_path / "run_a"
    (run / "records").mkdir(parents=True)
    (run / "records" / "settle_dem.csv").write_text("time[s],kinetic[J],contacts[1]\n0,1,0\n1,0.5,3\n2,0.25,4\n")
    # When compared with -y a,b
    result = CliRunner().invoke(cli, ["compare", str(run), "--record", "settle_dem", "-x", "time", "-y",
                                      "kinetic,contacts", "--out", str(tmp_path / "cmp")])
    # Then one figure per column
    assert result.exit_code == 0, result.output
    for col in ("kinetic", "contacts"):
        assert (tmp_path / "cmp" / f"settle_dem_{col}.csv").exists()


@pytest.mark.parametrize("text, value", [("256 GiB", 256 * 2 ** 30), ("64GB", 64e9), ("2e11", 2e11)])
def test_the_memory_of_another_machine_can_be_declared(monkeypatch, text, value):
    # Given a check made on a login node for a compute node (DEMCLI_MEMORY)
    from demcli.config import memory

    monkeypatch.setenv("DEMCLI_MEMORY", text)
    assert memory.machine_memory() == value


def test_a_count_the_declared_machine_holds_passes_and_a_bad_declaration_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("DEMCLI_MEMORY", "1 TiB")
    result, _ = _check(tmp_path, GOOD.replace("count: 5", "count: 100000000"))
    assert result.exit_code == 0, result.output
    monkeypatch.setenv("DEMCLI_MEMORY", "lots")
    result, _ = _check(tmp_path, GOOD)
    _refused(result, "DEMCLI_MEMORY='lots': give bytes")
