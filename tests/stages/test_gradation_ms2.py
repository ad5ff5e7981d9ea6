"""MS-2 volumetrics of the gradation stage's asphalt recipe: two published worked examples, the
stage writing them (state, CSV, ``demcli check``), and bad mix designs refused clearly.

Sources (the Asphalt Institute's own MS-2 example was not at hand; both use its relations):

* Course handout "Computation of volumetric properties in the Marshall mix design example"
  (course sheet "6506-9", https://www.coursehero.com/file/6271133/6506-9/): Gsb 2.683,
  Gb 1.05; Gmm 2.463 at 6.5 % binder gives Gse 2.717 and Pba 0.5 %; at 6.0 % binder and
  Gmb 2.364: Gmm 2.481, Pa 4.72 %, VMA 17.18 %, and Pbe as the 6.0 - 0.005 x 94 of its
  second Gmm formula. It prints VFA nowhere, so VFA is checked against 100 (VMA - Va) / VMA
  of its printed VMA and Va.
* Mamlouk & Zaniewski, "Materials for Civil and Construction Engineers", Sample Problem 9.2
  (Figure SP9.2; http://what-when-how.com/Tutorial/topic-1537ka2ksps/
  Materials-for-Civil-and-Construction-Engineers-369.html): 5 % binder (Gb 1.023), aggregate
  Gsb 2.755 with no absorption (Gse = Gsb), Gmb 2.441: VTM 3.9 %, VMA 15.8 %, VFA 75 %.

Tolerances are the rounding of the printed values (half a unit of their last digit), plus
what the handout's own rounding of an intermediate value carries (stated where it matters).
"""

import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.stages.specimen.gradation import MIX_NAMES, max_specific_gravity, ms2_volumetrics
from demcli.state import read_state


def test_marshall_course_example():
    # Given the handout's aggregate and binder: Gse from its Gmm at 6.5 % binder
    gsb, gse, gb = 2.683, 2.717, 1.05
    assert max_specific_gravity(gse, gb, 6.5) == pytest.approx(2.463, abs=5e-4)
    # When the 6.0 % specimen (Gmb 2.364) is analysed
    v = ms2_volumetrics(gsb, gse, gb, 6.0, 2.364)
    # Then every printed value comes back within its rounding
    assert v["Gmm"] == pytest.approx(2.481, abs=5e-4)
    assert v["Pba"] == pytest.approx(0.5, abs=0.05)
    assert v["Pbe"] == pytest.approx(6.0 - 0.005 * 94, abs=0.05 * 0.94)  # Pba's rounding, times Ps/100
    assert v["VMA"] == pytest.approx(17.18, abs=0.005)
    # Pa was printed from Gmm rounded to 2.481: that rounding alone moves it by up to 0.019
    assert v["Va"] == pytest.approx(4.72, abs=0.005 + 0.019)
    assert v["VFA"] == pytest.approx(100 * (17.18 - 4.72) / 17.18, abs=0.1)
    assert list(v) == list(MIX_NAMES)


def test_textbook_example_without_absorption():
    # Given 5 % binder (Gb 1.023), aggregate Gsb = Gse = 2.755 (no absorption), Gmb 2.441
    v = ms2_volumetrics(2.755, 2.755, 1.023, 5.0, 2.441)
    # Then VTM 3.9 %, VMA 15.8 %, VFA 75 % as printed, and no binder is absorbed
    assert v["Va"] == pytest.approx(3.9, abs=0.05)
    assert v["VMA"] == pytest.approx(15.8, abs=0.05)
    assert v["VFA"] == pytest.approx(75, abs=0.5)
    assert v["Pba"] == 0 and v["Pbe"] == 5.0


CASE = """\
name: ms2
dimension: 2
stages:
  - name: grading
    type: gradation
    sieves:  [1.18 mm, 2.36 mm, 4.75 mm, 9.5 mm, 13.2 mm, 16 mm]
    passing: [26.4,    37.6,    49.8,    79.7,   95,      100]
    specimen: {shape: circle, radius: 50 mm}
    volumetrics:
      kind: asphalt
      asphalt_content: 0.06
      aggregate_density: 2683 kg/m^3
      binder_density: 1.05 g/cm^3
      air_voids: 0.047
      min_size: 1.18 mm
      mix_design:
        aggregate_bulk_specific_gravity: 2.683
        aggregate_effective_specific_gravity: 2.717
        mix_bulk_specific_gravity: 2.364
"""


def _case(tmp_path, text):
    p = tmp_path / "ms2.yaml"
    p.write_text(text)
    return p


def test_stage_writes_the_volumetrics(tmp_path):
    # Given the handout's mix as an asphalt recipe (its Va 4.70 % within 0.1 of air_voids 4.7 %)
    p = _case(tmp_path, CASE)
    # When checked and run
    check = CliRunner().invoke(cli, ["check", str(p)])
    run_case(p, out=tmp_path / "run", quiet=True)
    # Then the state holds gradation/mix_design in MIX_NAMES order and the records/volumetrics row
    expected = ms2_volumetrics(2.683, 2.717, 1.05, 6.0, 2.364)
    st = read_state(tmp_path / "run" / "00-grading.h5")
    assert st.groups["gradation"]["mix_design"].tolist() == pytest.approx(list(expected.values()), rel=1e-12)
    table = st.groups["records/volumetrics"]
    assert {k: float(table[k][0]) for k in MIX_NAMES} == pytest.approx(expected, rel=1e-12)
    # and the CSV has one row with units in the header
    lines = (tmp_path / "run" / "records" / "grading_volumetrics.csv").read_text().splitlines()
    assert lines[0].split(",")[:5] == ["Gsb[1]", "Gse[1]", "Gb[1]", "Pb[%]", "Gmb[1]"] and len(lines) == 2
    assert [float(x) for x in lines[1].split(",")] == pytest.approx(list(expected.values()), rel=1e-12)
    # and demcli check prints Gmm, Va, VMA, VFA
    assert check.exit_code == 0, check.output
    assert "MS-2: Gmb 2.364 (given), Gmm 2.481, Va 4.7 %, VMA 17.2 %, VFA 72.6 %" in check.output


def test_gmb_defaults_to_the_air_voids(tmp_path):
    # Given no Gmb
    p = _case(tmp_path, CASE.replace("        mix_bulk_specific_gravity: 2.364\n", ""))
    run_case(p, out=tmp_path / "run", quiet=True)
    # Then Gmb = Gmm (1 - air_voids), so Va is the recipe's 4.7 %
    g = dict(zip(MIX_NAMES, read_state(tmp_path / "run" / "00-grading.h5").groups["gradation"]["mix_design"]))
    assert g["Gmb"] == pytest.approx(g["Gmm"] * (1 - 0.047), rel=1e-12)
    assert g["Va"] == pytest.approx(4.7, abs=1e-9)


def test_without_mix_design_nothing_is_written(tmp_path):
    # Given the recipe without a mix_design section
    p = _case(tmp_path, CASE.split("      mix_design:")[0])
    run_case(p, out=tmp_path / "run", quiet=True)
    # Then neither the field nor the table exists
    st = read_state(tmp_path / "run" / "00-grading.h5")
    assert "mix_design" not in st.groups["gradation"] and "records/volumetrics" not in st.groups
    assert not (tmp_path / "run" / "records" / "grading_volumetrics.csv").exists()


@pytest.mark.parametrize("old, new, needles", [
    ("aggregate_effective_specific_gravity: 2.717", "aggregate_effective_specific_gravity: 2.6",
     ["mix_design.aggregate_effective_specific_gravity", "must be >= the bulk specific gravity Gsb = 2.683",
      "absorbed binder is negative", "got 2.6"]),
    ("aggregate_effective_specific_gravity: 2.717", "aggregate_effective_specific_gravity: 3.3",
     ["mix_design.aggregate_effective_specific_gravity", "leaves no effective binder", "Pb = 6 %"]),
    ("mix_bulk_specific_gravity: 2.364", "mix_bulk_specific_gravity: 2.30",
     ["mix_design.mix_bulk_specific_gravity", "Va = 7.28 %", "air_voids is 4.7 %", "0.1 percentage point"]),
    ("aggregate_bulk_specific_gravity: 2.683", "aggregate_bulk_specific_gravity: 0",
     ["mix_design.aggregate_bulk_specific_gravity", "must be > 0"]),
    ("mix_bulk_specific_gravity: 2.364", "mix_bulk_specific_gravity: 2.364\n        gmm: 2.5",
     ["mix_design.gmm", "unknown key"]),
])
def test_bad_mix_designs_are_rejected(tmp_path, old, new, needles):
    # Given the valid case with one defect
    assert old in CASE
    p = _case(tmp_path, CASE.replace(old, new, 1))
    # When checked
    result = CliRunner().invoke(cli, ["check", str(p)])
    # Then exit code 2 with the place, the rule and the values
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)
