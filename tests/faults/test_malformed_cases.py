"""A generated fault suite: shipped cases mutated into well over a hundred malformed case files
(wrong types, non-finite and out-of-range quantities, wrong units, unknown and missing keys,
broken YAML, control characters, alias bombs, huge numbers, impossible stage orders, dangling
references, scenes too large for the machine). Each must be refused by ``demcli check`` with
exit code 2 and one clean message naming the file, never a traceback; a sample must also be
refused by ``demcli run`` before any stage runs (no state file written).

The mutations work on the data (read with demcli's loader, written back with PyYAML) or on the
text; ``test_unmutated_dumps_are_valid`` shows that the round trip alone keeps each case valid,
so each failure below comes from its mutation.
"""

import re
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from demcli.cli import cli
from demcli.config.load import load_yaml

CASES = Path(__file__).resolve().parents[2] / "cases"
BASES = ["smoke/beads.yaml", "quickstart.yaml", "smoke/marshall_2d.yaml", "smoke/asphalt_carved_cube.yaml",
         "smoke/sand_asphalt_uniaxial.yaml", "smoke/clumps.yaml"]

BOMB = "lol0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"lol{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]\n" for i in range(1, 9))


# ---------------------------------------------------------------------------------------
# data mutations: data (plain dicts and lists) -> None, in place
# ---------------------------------------------------------------------------------------

def _leaves(value, path=()):
    """(path, value) of every scalar under ``value``, in document order."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, path + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _leaves(v, path + (i,))
    else:
        yield path, value


def _set(data, path, value):
    node = data
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value


def _spread(items, n):
    """``n`` items spread evenly over ``items`` (all of them when fewer)."""
    if len(items) <= n:
        return items
    return [items[round(i * (len(items) - 1) / (n - 1))] for i in range(n)]


def _numbers(data):
    return [p for p, v in _leaves(data["stages"], ("stages",))
            if isinstance(v, (int, float)) and not isinstance(v, bool)]


def _quantities(data):
    return [p for p, v in _leaves(data, ()) if isinstance(v, str) and len(v.split()) == 2
            and v.split()[0].replace(".", "", 1).replace("e-", "", 1).lstrip("-").isdigit()]


def _setter(path, value):
    return lambda d: _set(d, path, value)


def _first_material(d):
    return next(iter(d["materials"]))


def _generic_mutations(data):
    """(label, mutation) pairs that break any case."""
    out = []
    for p in _spread(_numbers(data), 3):
        tag = "-".join(map(str, p[1:]))
        out += [(f"nan-{tag}", _setter(p, float("nan"))), (f"inf-{tag}", _setter(p, float("-inf"))),
                (f"text-{tag}", _setter(p, "lots"))]
    for p in _spread(_quantities(data), 3):
        number = _get(data, p).split()[0]
        out.append((f"unit-{'-'.join(map(str, p))}", _setter(p, f"{number} kg*s")))
    mat = _first_material(data)
    refs = [p for p, v in _leaves(data["stages"], ("stages",)) if p[-1] == "material"]
    out += [
        ("density-zero", lambda d: _set(d, ("materials", mat, "density"), 0)),
        ("density-negative", lambda d: _set(d, ("materials", mat, "density"), "-2500 kg/m^3")),
        ("young-negative", lambda d: _set(d, ("materials", mat, "young"), -1.0)),
        ("poisson-too-large", lambda d: _set(d, ("materials", mat, "poisson"), 0.5)),
        ("unknown-stage-key", lambda d: d["stages"][-1].update(frictoin=True)),
        ("unknown-top-key", lambda d: d.update(seeed=1)),
        ("missing-type", lambda d: d["stages"][0].pop("type")),
        ("missing-name", lambda d: d["stages"][-1].pop("name")),
        ("missing-stages", lambda d: d.pop("stages")),
        ("missing-density", lambda d: d["materials"][mat].pop("density")),
        ("stages-mapping", lambda d: d.update(stages={"a": 1})),
        ("stages-empty", lambda d: d.update(stages=[])),
        ("materials-list", lambda d: d.update(materials=[1, 2])),
        ("stage-string", lambda d: d["stages"].__setitem__(0, "generate")),
        ("unknown-type", lambda d: d["stages"][-1].update(type="dme")),
        ("type-list", lambda d: d["stages"][0].update(type=["generate"])),
        ("materials-null-name", lambda d: d["stages"][-1].update(material=None)),
        ("seed-text", lambda d: d.update(seed="abc")),
        ("seed-negative", lambda d: d.update(seed=-1)),
        ("seed-huge", lambda d: d.update(seed=2 ** 70)),
        ("seed-float", lambda d: d.update(seed=1.5)),
        ("dimension-4", lambda d: d.update(dimension=4)),
        ("bad-stage-name", lambda d: d["stages"][0].update(name="bad name!")),
        ("duplicate-stage-name", lambda d: d["stages"][0].update(name=d["stages"][-1]["name"])),
        ("reversed-stages", lambda d: d["stages"].reverse()),
        ("first-stage-dropped", lambda d: d["stages"].pop(0)),
        ("material-key-list", lambda d: d["materials"].update({"2bad": {"density": 1}})),
    ]
    out += [(f"unknown-material-{i}", _setter(p, "unobtainium")) for i, p in enumerate(_spread(refs, 2))]
    return out


def _get(data, path):
    node = data
    for p in path:
        node = node[p]
    return node


def _stage(d, type_name):
    return next(s for s in d["stages"] if s["type"] == type_name)


SPECIFIC = {  # faults of one case's stages: order, cross-stage rules, memory
    "smoke/beads.yaml": [
        ("box-max-below-min", lambda d: _stage(d, "dem")["walls"][0].update(max=[0.015, -0.015, 0.04])),
        ("box-flat", lambda d: _stage(d, "dem")["walls"][0].update(max=[0.015, 0.0, 0.04])),
        ("pressure-box-face", lambda d: _stage(d, "dem")["walls"][0].update(
            motion={"z0": {"mode": "pressure", "pressure": 1.0, "mass": 1.0}})),
        ("servo-plane-no-area", lambda d: _stage(d, "dem")["walls"].append(
            {"type": "plane", "point": [0, 0, 0.04], "normal": [0, 0, -1], "material": "steel",
             "motion": {"mode": "servo", "stress": 100.0}})),
        ("compact-after-generate", lambda d: _stage(d, "dem").update(
            type="compact", target={"porosity": 0.3})),
        ("count-1e9", lambda d: _stage(d, "generate").update(count=10 ** 9)),
        ("count-inf", lambda d: _stage(d, "generate").update(count=float("inf"))),
        ("lattice-overfull", lambda d: _stage(d, "generate").update(placement="lattice", count=100000)),
        ("radius-max-below-min", lambda d: _stage(d, "generate").update(radius={"min": "2 mm", "max": "1 mm"})),
        ("polyhedral-damping-on-spheres", lambda d: _stage(d, "dem")["physics"].update(contact_damping=True)),
        ("dt-factor-above-1", lambda d: _stage(d, "dem")["time"].update(dt_factor=2)),
        ("steps-and-duration", lambda d: _stage(d, "dem")["time"].update(duration="1 s")),
    ],
    "quickstart.yaml": [
        ("per-class-1", lambda d: _stage(d, "ballast_library").update(per_class=1)),
        ("library-seed-huge", lambda d: _stage(d, "ballast_library").update(seed=2 ** 64)),
        ("library-before-gradation", lambda d: d["stages"].insert(0, d["stages"].pop(1))),
        ("no-library", lambda d: d["stages"].pop(1)),
        ("rolling-on-polyhedra", lambda d: _stage(d, "deposit")["physics"].update(rolling_resistance=True)),
        ("cylinder-wall-on-polyhedra", lambda d: _stage(d, "deposit")["walls"].append(
            {"type": "cylinder", "base": [0.15, 0.1, 0], "axis": [0, 0, 1], "radius": "0.1 m", "height": "0.5 m",
             "material": "steel"})),
        ("planar-ballast", lambda d: d.update(dimension=2)),
        ("no-class-for-library", lambda d: _stage(d, "gradation").update(passing=[10, 20, 30, 40, 79, 95])),
    ],
    "smoke/marshall_2d.yaml": [
        ("dimension-3", lambda d: d.update(dimension=3)),
        ("other-specimen", lambda d: _stage(d, "polygons").update(specimen={"shape": "circle", "radius": "1 m"})),
        ("ball-radius-tiny", lambda d: _stage(d, "discretize").update(ball_radius="1 nm")),
        ("discretize-before-polygons", lambda d: d["stages"].insert(1, d["stages"].pop(2))),
    ],
    "smoke/asphalt_carved_cube.yaml": [
        ("region-max-below-min", lambda d: _stage(d, "place_spheres")["region"].update(max=[0, 0, 0])),
        ("lattice-count-huge", lambda d: _stage(d, "carve").update(lattice={"count": 10 ** 5})),
        ("lattice-spacing-too-large", lambda d: _stage(d, "carve").update(lattice={"spacing": "1 m"})),
        ("mastic-before-cut", lambda d: d["stages"].insert(4, d["stages"].pop(5))),
        ("mastic-ball-radius-tiny", lambda d: _stage(d, "mastic").update(ball_radius="10 nm")),
        ("carve-without-seeds", lambda d: d["stages"].pop(1)),
        ("seed-count-1e12", lambda d: _stage(d, "place_spheres").update(target={"kind": "count", "count": 10 ** 12})),
    ],
    "smoke/sand_asphalt_uniaxial.yaml": [
        ("prepare-count-1e10", lambda d: _stage(d, "prepare").update(count=10 ** 10)),
        ("prepare-sphere-too-big", lambda d: _stage(d, "prepare").update(count=2)),
        ("creep-first", lambda d: d["stages"].reverse()),
        ("bond-material-unknown", lambda d: _stage(d, "prepare")["bonds"]["models"][0].update(
            materials=["sand", "clay"])),
    ],
    "smoke/clumps.yaml": [
        ("planar-clumps", lambda d: d.update(dimension=2)),
    ],
}


# ---------------------------------------------------------------------------------------
# text mutations: text -> text (or bytes)
# ---------------------------------------------------------------------------------------

def _insert_after_line(text, n, chars):
    lines = text.splitlines(keepends=True)
    lines[n] = lines[n].rstrip("\n") + chars + "\n"
    return "".join(lines)


TEXT = [
    ("nul", lambda t: _insert_after_line(t, 1, "\x00")),
    ("bel-in-value", lambda t: t.replace("stages:", "stages:\x07", 1)),
    ("escape-in-comment", lambda t: "# \x1b[31m red\n" + t),
    ("delete-char", lambda t: _insert_after_line(t, 2, "\x7f")),
    ("form-feed", lambda t: t.replace("materials:", "\x0cmaterials:", 1)),
    ("unclosed-bracket", lambda t: t.replace("stages:", "stages: [", 1)),
    ("bad-indent", lambda t: t.replace("stages:", "stages:\n    x: 1\n  y: 2", 1)),
    ("tab-indent", lambda t: t.replace("\n  - name:", "\n\t- name:", 1)),
    ("unclosed-quote", lambda t: t + 'extra: "never closed\n'),
    ("duplicate-key", lambda t: t + "seed: 5\n"),
    ("alias-bomb", lambda t: BOMB + t),
    ("alias-bomb-in-stage", lambda t: BOMB.replace("lol", "x") + t),
    ("recursive-alias", lambda t: t + "loop: &r [*r]\n"),
    ("empty", lambda t: ""),
    ("comment-only", lambda t: "# nothing here\n"),
    ("top-level-list", lambda t: "- 1\n- 2\n"),
    ("too-large", lambda t: t + ("# padding\n" * 120_000)),
    ("deep-nesting", lambda t: t + "deep: " + "[" * 600 + "]" * 600 + "\n"),
    ("latin-1", lambda t: t.replace("materials:", "# caf\xe9\nmaterials:", 1).encode("latin-1")),
]


def _faults():
    out = []
    for base in BASES:
        text = (CASES / base).read_text()
        data, _ = load_yaml(text, base)
        stem = base.replace("/", "-").removesuffix(".yaml")
        for label, mutate in _generic_mutations(data) + SPECIFIC.get(base, []):
            out.append(pytest.param(stem, label, "data", base, mutate, id=f"{stem}-{label}"))
        for label, mutate in TEXT:
            out.append(pytest.param(stem, label, "text", base, mutate, id=f"{stem}-{label}"))
    return out


FAULTS = _faults()


def _write(tmp_path, stem, label, kind, base, mutate):
    """The mutated case file of a fault."""
    text = (CASES / base).read_text()
    path = tmp_path / f"{stem}-{label}.yaml"
    if kind == "text":
        out = mutate(text)
    else:
        data, _ = load_yaml(text, base)
        mutate(data)
        out = yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
    if isinstance(out, bytes):
        path.write_bytes(out)
    else:
        path.write_text(out, encoding="utf-8")
    return path


WHOLE_FILE = ("too-large", "latin-1")  # faults of the file as a whole: named by file, no line


def _assert_refused(result, path, label=""):
    """Exit code 2, one clean message, and every problem named by file and line (``file:N:``)
    or, for a file that cannot be read as a whole (size, encoding), by file alone."""
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output
    assert "Error" in result.output and path.name in result.output, result.output
    problems = [ln.strip() for ln in result.output.splitlines()[1:] if ln.strip()] or [result.output.strip()]
    for line in problems:
        where = "" if label in WHOLE_FILE else r":\d+"
        assert re.match(rf"(Error: (invalid case \(1 problem\): )?)?{re.escape(str(path))}{where}: \S", line), line


def test_the_suite_is_large():
    # Given the generated faults, Then there are well over a hundred of them
    assert len(FAULTS) >= 100


@pytest.mark.parametrize("base", BASES)
def test_unmutated_dumps_are_valid(tmp_path, base):
    # Given a shipped case read and written back unchanged
    path = _write(tmp_path, "base", "none", "data", base, lambda d: None)
    # When checked
    result = CliRunner().invoke(cli, ["check", str(path)])
    # Then it is valid: a fault below comes from its mutation
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("stem, label, kind, base, mutate", FAULTS)
def test_check_refuses_with_one_clean_message(tmp_path, stem, label, kind, base, mutate):
    # Given a shipped case with one fault
    path = _write(tmp_path, stem, label, kind, base, mutate)
    # When checked
    result = CliRunner().invoke(cli, ["check", str(path)])
    # Then: exit code 2, "Error: ..." naming the file and the line of each problem, no traceback
    _assert_refused(result, path, label)


RUN_SAMPLE = ["smoke-beads-compact-after-generate", "smoke-beads-count-1e9", "smoke-beads-box-max-below-min",
              "quickstart-per-class-1", "quickstart-library-before-gradation", "quickstart-alias-bomb",
              "smoke-beads-nul", "smoke-sand_asphalt_uniaxial-creep-first", "smoke-marshall_2d-dimension-3",
              "smoke-beads-unknown-material-0"]


@pytest.mark.parametrize("stem, label, kind, base, mutate", [f for f in FAULTS if f.id in RUN_SAMPLE])
def test_run_refuses_before_any_stage_runs(tmp_path, stem, label, kind, base, mutate):
    # Given a faulty case and a run folder
    path = _write(tmp_path, stem, label, kind, base, mutate)
    out = tmp_path / "run"
    # When run
    result = CliRunner().invoke(cli, ["run", str(path), "--out", str(out), "--quiet"])
    # Then it is refused as check refuses it, and no stage ran: no state file anywhere
    _assert_refused(result, path)
    assert not list(tmp_path.rglob("*.h5"))


def test_the_run_sample_is_in_the_suite():
    # Given the run sample's ids, Then each names a generated fault
    assert len([f for f in FAULTS if f.id in RUN_SAMPLE]) == len(RUN_SAMPLE)
