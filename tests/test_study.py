"""``demcli study``: parsing and validation, the grid, the metric, the errors, and a real study."""

import csv
import math
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from demcli.cli import cli
from demcli.errors import InputError
from demcli.study import (Metric, error_table, make_variants, parse_metric, parse_realisations, parse_vary,
                          pick_reference, read_metric, reduce_column, split_values, validate_variants,
                          check_metric_stage)

CASES = Path(__file__).resolve().parent.parent / "cases"
IMPACT = CASES / "studies" / "timestep_impact.yaml"
# the shipped impact study made tiny: 100 spheres in one row, guards checked every step
TINY = ["--set", "stages.layer.count=100", "--set", "stages.impact.safety.check_every=1"]
DT = "stages.impact.time.dt_factor"


def _invoke(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _assert_clean_error(result, *needles, code=2):
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output, (needle, result.output)


# ---- parsing -----------------------------------------------------------------------------

def test_values_split_at_top_level_commas_only():
    assert split_values("0.4, 0.2,0.1") == ["0.4", "0.2", "0.1"]
    assert split_values("[1, 2],[3, 4]") == ["[1, 2]", "[3, 4]"]
    assert split_values('"1, 2 mm",{min: 1 mm, max: 2 mm}') == ['"1, 2 mm"', "{min: 1 mm, max: 2 mm}"]


def test_vary_keeps_values_as_written():
    v = parse_vary("stages.pour.radius.min=1 mm,2 mm")
    assert v.path == "stages.pour.radius.min" and v.values == ("1 mm", "2 mm")


@pytest.mark.parametrize("text, needle", [
    ("stages.settle.time.dt_factor", "write PATH=V1,V2"),
    ("=0.1,0.2", "write PATH=V1,V2"),
    ("stages..dt_factor=0.1", "empty segment"),
    ("stages.settle.time.dt_factor=0.1,,0.2", "empty value"),
    ("stages.settle.time.dt_factor=0.1,", "empty value"),
    ("stages.settle.time.dt_factor=0.1,0.2,0.1", "given twice"),
])
def test_bad_vary_is_named(text, needle):
    with pytest.raises(InputError, match=needle):
        parse_vary(text)


@pytest.mark.parametrize("text, parsed", [
    ("settle.dem.kinetic", ("settle", "dem", "kinetic", "last")),
    ("settle.dem.kinetic@max", ("settle", "dem", "kinetic", "max")),
    ("impact.walls.floor.force@mean", ("impact", "walls", "floor.force", "mean")),
])
def test_metric_parses(text, parsed):
    assert parse_metric(text) == Metric(*parsed)


@pytest.mark.parametrize("text, needle", [
    ("settle.kinetic", "STAGE.TABLE.COLUMN"),
    ("settle..kinetic", "STAGE.TABLE.COLUMN"),
    ("settle.dem.kinetic@median", "unknown reducer @median"),
])
def test_bad_metric_is_named(text, needle):
    with pytest.raises(InputError, match=needle):
        parse_metric(text)


# ---- the grid and the reference ------------------------------------------------------------

def test_several_varies_make_a_grid_first_slowest():
    varies, variants = make_variants([parse_vary("stages.a.time.dt_factor=0.4,0.2,0.1"),
                                      parse_vary("stages.pour.count=10,20")])
    assert len(variants) == 6
    assert [v.label for v in varies] == ["dt_factor", "count"]
    assert variants[0].slug == "dt_factor=0.4,count=10" and variants[1].slug == "dt_factor=0.4,count=20"
    assert variants[-1].overrides(varies) == ["stages.a.time.dt_factor=0.1", "stages.pour.count=20"]
    # Then the finest is each list's last value, unless told otherwise
    assert pick_reference(varies, variants) == 5
    assert pick_reference(varies, variants, "first") == 0
    assert pick_reference(varies, variants, "dt_factor=0.2,count=10") == 2
    with pytest.raises(InputError, match="no such variant.*dt_factor=0.4,count=10"):
        pick_reference(varies, variants, "dt_factor=0.3")


def test_labels_grow_until_unique_and_values_become_folder_names():
    varies, variants = make_variants([parse_vary("stages.a.time.dt_factor=0.1"),
                                      parse_vary("stages.b.time.dt_factor=0.2"),
                                      parse_vary("stages.pour.radius.min=1 mm,2.5 mm")])
    assert [v.label for v in varies] == ["a.time.dt_factor", "b.time.dt_factor", "min"]
    assert variants[1].slug == "a.time.dt_factor=0.1,b.time.dt_factor=0.2,min=2.5mm"
    with pytest.raises(InputError, match="same folder"):
        make_variants([parse_vary("stages.pour.radius.min=1 mm,1mm")])
    with pytest.raises(InputError, match="varied twice"):
        make_variants([parse_vary("seed=1,2"), parse_vary("seed=3")])


def test_a_plus_vary_pairs_with_the_one_before_instead_of_crossing():
    # Given two paths varied together (+) and a third crossing them
    varies, variants = make_variants([parse_vary("stages.deposit.scaling.stiffness=0.01,0.001,0.0001"),
                                      parse_vary("+stages.vibrate.scaling.stiffness=0.01,0.001,0.0001"),
                                      parse_vary("seed=1,2")])
    # Then the pair is one axis of the grid: 3 x 2 variants, not 3 x 3 x 2
    assert len(variants) == 6
    assert [v.group for v in varies] == [0, 0, 1] and [v.along for v in varies] == [False, True, False]
    assert variants[2].overrides(varies) == ["stages.deposit.scaling.stiffness=0.001",
                                             "stages.vibrate.scaling.stiffness=0.001", "seed=1"]
    # and folders are named by the first path of each axis; the reference is the last pair
    assert variants[2].slug == "deposit.scaling.stiffness=0.001,seed=1"
    assert variants[pick_reference(varies, variants)].values == ("0.0001", "0.0001", "2")
    # and a study reads its values with the +, spaces allowed
    assert parse_vary(" + stages.b.count=1,2") == parse_vary("+stages.b.count=1,2")


@pytest.mark.parametrize("texts, needle", [
    (["+stages.b.count=1,2"], "there is none"),
    (["stages.a.time.dt_factor=0.4,0.2", "+stages.b.count=1,2,3"], "3 values to pair with the 2"),
    (["stages.a.time.dt_factor=0.4,0.2", "+stages.a.time.dt_factor=0.1,0.05"], "varied twice"),
])
def test_a_bad_plus_vary_is_named(texts, needle):
    with pytest.raises(InputError, match=needle):
        make_variants([parse_vary(t) for t in texts])


def test_every_variant_is_validated_before_any_runs():
    varies, variants = make_variants([parse_vary(f"{DT}=0.5,2,3")])
    with pytest.raises(InputError) as info:
        validate_variants(IMPACT, varies, variants)
    text = str(info.value.format_message())
    # Then the two bad variants are named with the case's rule; the good one is not
    assert "2 of 3 variants" in text and "nothing was run" in text
    assert "variant dt_factor=2:" in text and "variant dt_factor=3:" in text and "dt_factor=0.5:" not in text
    assert "must be in (0, 1]" in text


# the shipped studies: the files whose header reads "# Study: ..." (a study's reference case is a plain run)
STUDIES = [p for p in sorted((CASES / "studies").glob("*.yaml")) if p.read_text().startswith("# Study")]


@pytest.mark.parametrize("study", STUDIES, ids=lambda p: p.name)
def test_the_shipped_study_commands_are_valid(study):
    # Given the command line written in a shipped study's header
    lines = [ln[1:].strip() for ln in study.read_text().splitlines() if ln.startswith("#")]
    start = next(i for i, ln in enumerate(lines) if ln.startswith("demcli study"))
    text = ""
    for ln in lines[start:]:
        text += ln.rstrip("\\").strip() + " "
        if not ln.endswith("\\"):
            break
    args = shlex.split(text)
    assert args[2] == f"cases/studies/{study.name}"
    varies = [parse_vary(args[k + 1]) for k, a in enumerate(args) if a == "--vary"]
    varies += [parse_realisations(args[k + 1]) for k, a in enumerate(args) if a == "--realisations"]
    fixed = [args[k + 1] for k, a in enumerate(args) if a == "--set"]
    metric = parse_metric(args[args.index("--metric") + 1])
    # Then its variants and metric validate against the case
    varies, variants = make_variants(varies)
    check_metric_stage(metric, validate_variants(study, varies, variants, fixed))


# ---- the metric and the errors ---------------------------------------------------------------

def test_metric_reduces_a_record_column(tmp_path):
    # Given a hand-made record CSV as the stages write them
    (tmp_path / "records").mkdir()
    (tmp_path / "records" / "settle_dem.csv").write_text(
        "time[s],kinetic[J],walls.floor.force[N]\n0.0,4.0,1\n0.1,1.0,3\n0.2,2.5,2\n")
    # Then each reducer gives its number, with the column's unit
    expect = {"last": 2.5, "first": 4.0, "max": 4.0, "min": 1.0, "mean": 2.5}
    for reducer, value in expect.items():
        assert read_metric(tmp_path, parse_metric(f"settle.dem.kinetic@{reducer}")) == (value, "J")
    assert read_metric(tmp_path, parse_metric("settle.dem.walls.floor.force@max")) == (3.0, "N")
    # and a missing table or column is named with what there is
    with pytest.raises(InputError, match="no record table 'energy'.*its tables: dem"):
        read_metric(tmp_path, parse_metric("settle.energy.total"))
    with pytest.raises(InputError, match="no column 'kinetc'; columns: time, kinetic"):
        read_metric(tmp_path, parse_metric("settle.dem.kinetc"))
    with pytest.raises(InputError, match="no rows"):
        reduce_column([], "last")


def test_errors_against_the_reference():
    errs = error_table([1.0, 1.5, 2.0], ref=2)
    assert errs[2] == (0.0, 0.0)
    assert errs[0] == (-1.0, 0.5) and errs[1] == (-0.5, 0.25)
    # a zero or missing reference leaves relative errors undefined, a missing value its error
    assert math.isnan(error_table([1.0, 0.0], ref=1)[0][1])
    e, r = error_table([math.nan, 2.0], ref=1)[0]
    assert math.isnan(e) and math.isnan(r)


# ---- the command ---------------------------------------------------------------------------

@pytest.mark.parametrize("args, needles", [
    (["--vary", f"{DT}=0.2,0.1", "--metric", "impact.dem"], ["STAGE.TABLE.COLUMN"]),
    (["--vary", f"{DT}=0.2,0.1", "--metric", "impakt.dem.kinetic"], ["no stage 'impakt'", "did you mean 'impact'"]),
    (["--vary", f"{DT}=0.2,0.1", "--metric", "impact.dem.kinetic", "--reference", "dt_factor=0.3"],
     ["--reference dt_factor=0.3", "dt_factor=0.2, dt_factor=0.1"]),
    (["--vary", "stages.impact.time.dt_factr=0.2,0.1", "--metric", "impact.dem.kinetic"],
     ["variant dt_factr=0.2", "unknown key", "did you mean 'dt_factor'"]),
    (["--vary", "stages.impakt.time.dt_factor=0.2,0.1", "--metric", "impact.dem.kinetic"],
     ["variant dt_factor=0.1", "no item named 'impakt'"]),
    (["--vary", f"{DT}=0.2,0.1", "--set", f"{DT}=0.3", "--metric", "impact.dem.kinetic"], ["also varied"]),
    (["--metric", "impact.dem.kinetic"], ["Missing option '--vary'"]),
])
def test_bad_study_exits_2_before_running(tmp_path, args, needles):
    result = _invoke(["study", IMPACT, "--out", tmp_path / "s", *args])
    _assert_clean_error(result, *needles)
    assert not list((tmp_path / "s").glob("*/*.h5"))


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    """The tiny impact study, run one variant at a time."""
    out = tmp_path_factory.mktemp("study") / "serial"
    result = _invoke(["study", IMPACT, *TINY, "--vary", f"{DT}=0.4,0.2,0.1", "--metric", "impact.dem.kinetic@last",
                      "--out", out, "--jobs", "1"])
    assert result.exit_code == 0, result.output
    return out, result


def test_study_writes_its_reports(tiny_study):
    out, result = tiny_study
    # Then the three reports exist, one run folder per variant, and the table is printed
    for name in ("study.csv", "study.md", "study.png", "study.json"):
        assert (out / name).stat().st_size > 0, name
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["dt_factor=0.1", "dt_factor=0.2", "dt_factor=0.4"]
    assert "| dt_factor | kinetic@last [J] | error [J] | rel. error | wall time [s] |" in result.output
    assert (out / "study.md").read_text() in result.output
    rows = _rows(out / "study.csv")
    assert [r["dt_factor"] for r in rows] == ["0.4", "0.2", "0.1"]
    # and the finest variant has zero error, the others a nonzero one and a wall time
    assert float(rows[-1]["error[J]"]) == 0.0 and rows[-1]["status"] == "ran (reference)"
    for r in rows:
        assert float(r["kinetic@last[J]"]) > 0 and float(r["wall_time[s]"]) > 0
    assert all(float(r["rel_error"]) > 0 for r in rows[:-1])


def test_up_to_date_variants_keep_their_wall_time(tiny_study):
    out, _ = tiny_study
    before = _rows(out / "study.csv")
    # When the same study is run again
    result = _invoke(["study", IMPACT, *TINY, "--vary", f"{DT}=0.4,0.2,0.1", "--metric", "impact.dem.kinetic@last",
                      "--out", out, "--jobs", "1"])
    assert result.exit_code == 0, result.output
    after = _rows(out / "study.csv")
    # Then nothing ran, and the metric and wall times are the stored ones
    assert all(r["status"].startswith("reused") for r in after)
    for a, b in zip(before, after):
        assert a["kinetic@last[J]"] == b["kinetic@last[J]"] and a["wall_time[s]"] == b["wall_time[s]"]


def test_a_metric_the_records_lack_exits_2(tiny_study):
    out, _ = tiny_study
    result = _invoke(["study", IMPACT, *TINY, "--vary", f"{DT}=0.4,0.2,0.1", "--metric", "impact.dem.kinetc",
                      "--out", out, "--jobs", "1"])
    _assert_clean_error(result, "no column 'kinetc'", "columns: time, step, kinetic")


def test_parallel_jobs_give_the_serial_numbers(tiny_study, tmp_path):
    out, _ = tiny_study
    # When the same study runs two variants at a time, in spawned workers
    result = _invoke(["study", IMPACT, *TINY, "--vary", f"{DT}=0.4,0.2,0.1", "--metric", "impact.dem.kinetic@last",
                      "--out", tmp_path / "parallel", "--jobs", "2", "--quiet"])
    assert result.exit_code == 0, result.output
    serial, parallel = _rows(out / "study.csv"), _rows(tmp_path / "parallel" / "study.csv")
    # Then every metric and error is bit-identical
    for a, b in zip(serial, parallel):
        assert a["variant"] == b["variant"] and b["status"].startswith("ran")
        assert a["kinetic@last[J]"] == b["kinetic@last[J]"] and a["error[J]"] == b["error[J]"]


def test_paths_varied_together_run_as_pairs(tmp_path):
    # When the step and the duration are varied together (two variants, not four)
    result = _invoke(["study", IMPACT, *TINY, "--vary", f"{DT}=0.4,0.2", "--vary",
                      "+stages.impact.time.duration=1e-4 s,1.2e-4 s", "--metric", "impact.dem.time@last",
                      "--out", tmp_path, "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    # Then each variant ran with its pair of values, in a folder named by the first path
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == ["dt_factor=0.2", "dt_factor=0.4"]
    rows = _rows(tmp_path / "study.csv")
    assert [(r["dt_factor"], r["duration"]) for r in rows] == [("0.4", "1e-4 s"), ("0.2", "1.2e-4 s")]
    assert [float(r["time@last[s]"]) for r in rows] == pytest.approx([1e-4, 1.2e-4], rel=0.05)
    assert "| dt_factor | duration | time@last [s] |" in result.output


def test_a_failing_variant_is_reported_and_the_study_goes_on(tmp_path):
    # Given a variant whose overlap guard trips on the first contact
    args = ["study", IMPACT, *TINY, "--set", f"{DT}=0.2", "--vary", "stages.impact.safety.energy_limit=1,1000",
            "--metric", "impact.dem.kinetic", "--out", tmp_path, "--jobs", "1"]
    result = _invoke(args)
    # Then the study finishes, with the failure in the status column and no number for it
    assert result.exit_code == 0, result.output
    rows = _rows(tmp_path / "study.csv")
    assert rows[0]["status"].startswith("failed: stage impact stopped") and rows[0]["kinetic@last[J]"] == ""
    assert rows[1]["status"] == "ran (reference)"
    assert "1 variant(s) failed" in result.output
    # and when the failing variant is the reference, there is nothing to compare against: exit 1
    result = _invoke(args + ["--reference", "first"])
    _assert_clean_error(result, "the reference variant energy_limit=1 failed", code=1)


def test_ctrl_c_in_a_variant_stops_the_study(tmp_path, monkeypatch):
    # Given a run that is interrupted (the dem stage turns Ctrl-C into a StageError)
    import demcli.pipeline
    from demcli.errors import StageError
    from demcli.study import run_study

    def interrupted(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise StageError("stage impact interrupted at step 7; continue with --resume") from None

    monkeypatch.setattr(demcli.pipeline, "run_case", interrupted)
    # Then the study stops at once instead of going on to the next variant
    with pytest.raises(StageError, match="study interrupted in variant dt_factor=0.2"):
        run_study(IMPACT, [f"{DT}=0.2,0.1"], "impact.dem.kinetic", out=tmp_path, jobs=1)


def _children(pid):
    """PIDs of the processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_sigterm_stops_a_parallel_study_and_its_workers(tmp_path, wait_for_files):
    # Given a study whose two variants would step for tens of seconds, each in a spawned worker,
    # checkpointing at every record (so a checkpoint file shows that a variant is stepping)
    long = ["--set", "stages.impact.time.duration=0.05 s", "--set", "stages.impact.output.records=100",
            "--set", "stages.impact.output.checkpoint=1e-9 s"]
    cmd = [sys.executable, "-m", "demcli", "study", IMPACT, *TINY, *long, "--vary", f"{DT}=0.002,0.001",
           "--metric", "impact.dem.kinetic@last", "--out", tmp_path, "--jobs", "2", "--cold", "--quiet"]
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    folders = [tmp_path / "dt_factor=0.002", tmp_path / "dt_factor=0.001"]
    wait_for_files(proc, [f / "01-impact.ckpt.h5" for f in folders])
    workers = _children(proc.pid)
    # When the study process alone gets SIGTERM (`kill`, a batch system's time limit)
    proc.terminate()
    _, err = proc.communicate(timeout=120)
    # Then it stops with a message and no traceback,
    assert proc.returncode == 1, err
    assert "study interrupted" in err and "Traceback" not in err, err
    # its workers stopped their variants there (through the checkpoint path) and are gone
    assert not [f for f in folders if (f / "01-impact.h5").exists()]
    assert all("interrupted at step" in (f / "log.txt").read_text() for f in folders)
    assert len(workers) >= 2
    deadline = time.monotonic() + 10  # multiprocessing's resource tracker leaves once its pipe closes
    while [p for p in workers if _alive(p)] and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [p for p in workers if _alive(p)]


# ---- realisations ------------------------------------------------------------------------

def _synthetic(metrics_by_setting, real_values=("1", "2", "3")):
    """Rows of a study over dt_factor with seed realisations, metrics given per setting."""
    from demcli.study import Row

    varies, variants = make_variants([parse_vary("stages.s.time.dt_factor=" + ",".join(metrics_by_setting)),
                                      parse_realisations("seed=" + ",".join(real_values))])
    rows = []
    for var in variants:
        k = real_values.index(var.values[-1])
        rows.append(Row(var, metric=metrics_by_setting[var.values[0]][k], wall_time=float(k + 1)))
    return varies, variants, rows


def test_realisations_reduce_to_mean_spread_and_resolution():
    from demcli.study_stats import aggregate

    # Given two settings with three realisations each
    varies, variants, rows = _synthetic({"0.2": [1.0, 2.0, 3.0], "0.1": [5.0, 5.5, 6.0]})
    assert [v.slug for v in variants[:2]] == ["dt_factor=0.2,seed=1", "dt_factor=0.2,seed=2"]
    # When they are aggregated against the last setting
    settings, ref = aggregate(varies, rows, pick_reference(varies, variants, "last"))
    # Then each setting has the sample statistics of its runs
    assert ref == 1 and [s.values for s in settings] == [("0.2",), ("0.1",)]
    a, b = settings
    assert (a.n, a.mean, a.std) == (3, 2.0, 1.0) and a.sem == pytest.approx(1 / math.sqrt(3), rel=1e-15)
    assert (b.mean, b.std) == (5.5, 0.5) and a.wall_time == 2.0
    # and the error of the mean in units of the combined standard error: 3.5 / sqrt(1/3 + 1/12)
    assert a.error == -3.5 and a.resolution == pytest.approx(3.5 / math.sqrt(1 / 3 + 0.25 / 3), rel=1e-14)
    assert math.isnan(b.resolution) and b.error == 0.0


def test_a_failed_realisation_is_left_out_of_its_setting():
    from demcli.study_stats import aggregate, settings_markdown

    varies, variants, rows = _synthetic({"0.2": [1.0, math.nan, 3.0], "0.1": [5.0, 5.5, 6.0]})
    settings, ref = aggregate(varies, rows, len(rows) - 1)
    assert (settings[0].n, settings[0].runs, settings[0].mean) == (2, 3, 2.0)
    assert "| 0.2 | 2 of 3 | 2 |" in settings_markdown(varies, settings, ref, "x@last", "m")


def test_a_setting_name_picks_the_reference_of_a_study_with_realisations():
    varies, variants, _ = _synthetic({"0.2": [1, 2, 3], "0.1": [1, 2, 3]})
    assert variants[pick_reference(varies, variants, "dt_factor=0.2")].values[0] == "0.2"


@pytest.mark.parametrize("text, needle", [("seed=1", "two values or more"), ("+seed=1,2", "drop the +")])
def test_bad_realisations_are_named(text, needle):
    with pytest.raises(InputError, match=needle):
        parse_realisations(text)


def test_a_study_with_realisations_reports_each_setting(tmp_path):
    # Given realisations whose metric is known: the duration, so time@last = 1e-4 s or 1.2e-4 s
    result = _invoke(["study", IMPACT, *TINY, "--vary", f"{DT}=0.4,0.2", "--realisations",
                      "stages.impact.time.duration=1e-4 s,1.2e-4 s", "--metric", "impact.dem.time@last",
                      "--out", tmp_path, "--jobs", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    # Then four runs are reduced to two settings of mean 1.1e-4 s and standard deviation sqrt(2) 1e-5 s
    settings = _rows(tmp_path / "settings.csv")
    assert [s["dt_factor"] for s in settings] == ["0.4", "0.2"] and settings[1]["reference"] == "yes"
    for s in settings:
        assert s["n"] == "2" and float(s["time@last_mean[s]"]) == pytest.approx(1.1e-4, rel=0.02)
        assert float(s["std[s]"]) == pytest.approx(math.sqrt(2) * 1e-5, rel=0.1)
    assert (tmp_path / "settings.png").stat().st_size > 0
    assert "Realisations: `stages.impact.time.duration`" in result.output
    # and each run's error is taken against the reference setting's mean
    runs = _rows(tmp_path / "study.csv")
    ref_mean = float(settings[1]["time@last_mean[s]"])
    for r in runs:
        assert float(r["error[s]"]) == pytest.approx(float(r["time@last[s]"]) - ref_mean, abs=1e-18)


def test_paths_varied_together_make_one_line_of_the_settings_plot(tmp_path):
    from demcli.study import Row
    from demcli.study_stats import _series, aggregate, write_settings_plot

    # Given a stiffness varied in two stages together, crossed with a count, three seeds each
    varies, variants = make_variants([parse_vary("stages.a.k=0.001,0.01"), parse_vary("+stages.b.k=0.001,0.01"),
                                      parse_vary("stages.a.n=10,20"), parse_realisations("seed=1,2,3")])
    rows = [Row(v, metric=float(k), wall_time=1.0 + k) for k, v in enumerate(variants)]
    settings, _ = aggregate(varies, rows, len(rows) - 1)
    # Then the plot has one line per count, each through both stiffnesses (the paired path is no line)
    series = _series(varies, settings)
    assert sorted(series) == ["n=10", "n=20"] and all(len(s) == 2 for s in series.values())
    assert write_settings_plot(tmp_path / "s.png", "case.yaml", varies, settings, "x@last", "m")
