"""``demcli sweep``: the sweep file, its grid, its errors, and real sweeps on Dask clusters.

Runs are the beads smoke case cut to 300 steps (a few seconds each). The clusters are
closed by the code under test (--workers) or by the fixture that starts them (--scheduler).
"""

import csv
import os
import time
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from demcli.cli import cli
from demcli.sweep import _error_line, _text, check_sweep, plan_sweep

BEADS = Path(__file__).resolve().parent.parent / "cases" / "smoke" / "beads.yaml"
SHORT = "stages.settle.time.steps: 300"


def _invoke(args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _sweep_file(tmp_path, body, name="sweep.yaml"):
    """A sweep file in tmp_path; ``CASE`` in ``body`` is the beads smoke case, relative to it."""
    p = tmp_path / name
    p.write_text(body.replace("CASE", os.path.relpath(BEADS, tmp_path)))
    return p


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _record(run_dir, column):
    """A column of records/settle_dem.csv, read here without demcli."""
    rows = _rows(Path(run_dir) / "records" / "settle_dem.csv")
    return [float(r[column]) for r in rows]


# ---- the sweep file and its grid (no cluster) ----------------------------------------------

@pytest.mark.parametrize("seeds, needle", [("[1180591620717411303424]", "seeds[0]: must be <="),
                                           ("{first: 9223372036854775800, count: 10}", "seeds.count: the last seed")])
def test_seeds_beyond_64_bits_fail_the_sweep_check(tmp_path, seeds, needle):
    # Given seeds a state file cannot hold (#27 item 6: each run failed after its first stage)
    path = _sweep_file(tmp_path, f"seeds: {seeds}\nruns:\n  - case: CASE\n")
    # Then the sweep check refuses them, naming the key
    result = _invoke(["sweep", path, "--check"])
    assert result.exit_code == 2 and needle in result.output and "Traceback" not in result.output, result.output


def test_seeds_and_vary_expand_to_a_grid(tmp_path):
    # Given a run with two dt factors and three seeds, and a top-level set that the run extends
    path = _sweep_file(tmp_path, f"""\
set: {{{SHORT}, stages.pour.count: 100}}
seeds: [7]
runs:
  - case: CASE
    set: {{stages.pour.count: 120}}
    vary: {{stages.settle.time.dt_factor: [0.25, 0.1]}}
    seeds: {{first: 1, count: 3}}
  - {{case: CASE, name: plain}}
""")
    # When it is planned
    plan = plan_sweep(path, out=tmp_path / "out")
    # Then the run's seeds replace the top-level ones, the first path changes slowest, seeds fastest
    ids = [r.id for r in plan.runs]
    assert ids == [f"beads/dt_factor={dt},seed={s}" for dt in ("0.25", "0.1") for s in (1, 2, 3)] + ["plain/seed=7"]
    first = plan.runs[0]
    assert first.overrides == ["stages.settle.time.steps=300", "stages.pour.count=120",
                               "stages.settle.time.dt_factor=0.25", "seed=1"]
    assert first.folder == tmp_path / "out" / "beads" / "dt_factor=0.25,seed=1"
    assert first.case_path.resolve() == BEADS and not first.problem
    assert plan.runs[-1].overrides == ["stages.settle.time.steps=300", "stages.pour.count=100", "seed=7"]


def test_a_plus_path_pairs_its_values_with_the_path_before_it(tmp_path):
    # Given two paths varied together (+path) and one crossing them
    path = _sweep_file(tmp_path, f"""\
set: {{{SHORT}}}
runs:
  - case: CASE
    vary:
      stages.settle.time.dt_factor: [0.25, 0.1]
      +stages.pour.count: [100, 120]
      stages.pour.radius.min: [1 mm, 2 mm]
""")
    # When it is planned
    plan = plan_sweep(path, out=tmp_path / "out")
    # Then the paired paths make one axis (2 x 2 runs, not 2 x 2 x 2), both written as overrides
    assert [r.id for r in plan.runs] == [f"beads/dt_factor={dt},min={m}" for dt in ("0.25", "0.1")
                                         for m in ("1mm", "2mm")]
    assert plan.runs[2].overrides == ["stages.settle.time.steps=300", "stages.settle.time.dt_factor=0.1",
                                      "stages.pour.count=120", "stages.pour.radius.min=1 mm"]
    # And a + path with a different number of values is refused with its key
    bad = _sweep_file(tmp_path, "runs:\n  - case: CASE\n    vary:\n      stages.settle.time.dt_factor: [0.25, 0.1]\n"
                                "      +stages.pour.count: [100]\n", name="bad.yaml")
    result = _invoke(["sweep", bad, "--check"])
    assert result.exit_code == 2 and "runs[0].vary" in result.output and "pair" in result.output, result.output


@pytest.mark.parametrize("value, text", [("2 mm", "2 mm"), ([0, 0, -9.81], "[0, 0, -9.81]"), (1e-5, "1.0e-05"),
                                         ("3", "'3'"), (True, "true"), ({"mu": 0.3}, "{mu: 0.3}")])
def test_values_are_written_as_set_reads_them(value, text):
    from demcli.config.load import _parse_override_value

    assert _text(value) == text
    assert _parse_override_value(text) == value


def test_bad_sweep_file_names_file_line_key_and_rule(tmp_path):
    path = _sweep_file(tmp_path, """\
metrics: [settle.dem.kinetic@median]
runs:
  - case: CASE
    sed: [1, 2]
cluster: {type: slurmm}
""", name="bad.yaml")
    result = _invoke(["sweep", path])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "invalid sweep file (3 problems)" in result.output
    assert f"{path}:1: metrics[0]: unknown reducer @median" in result.output
    assert f"{path}:4: runs[0].sed: unknown key; did you mean 'seeds'?" in result.output
    assert f"{path}:5: cluster.type: must be one of 'local', 'slurm', 'pbs' (got 'slurmm')" in result.output


def test_conflicting_generators_are_refused_with_their_line(tmp_path):
    path = _sweep_file(tmp_path, """\
runs:
  - case: CASE
    set: {seed: 3}
    seeds: [1, 2]
  - case: CASE
""")
    result = _invoke(["sweep", path])
    assert result.exit_code == 2, result.output
    assert f"{path}:4: runs[0].seeds: seed is also given in set" in result.output
    assert f"{path}:5: runs[1].case: run folder 'beads' is also used by runs[0]" in result.output


def test_a_run_whose_case_is_invalid_fails_alone_and_check_lists_it(tmp_path):
    path = _sweep_file(tmp_path, """\
runs:
  - {case: missing.yaml}
  - {case: CASE, set: {stages.settle.time.dt_factor: 5}}
""")
    result = _invoke(["sweep", path, "--check"])
    assert result.exit_code == 2, result.output
    assert "INVALID: invalid case: " in result.output and "file not found" in result.output
    assert "2 of 2 runs fail validation" in result.output
    # all runs are invalid: nothing is started (no cluster), the table says why, exit 1
    result = _invoke(["sweep", path, "--out", tmp_path / "out"])
    assert result.exit_code == 1, result.output
    status = {r["run"]: r["status"] for r in _rows(tmp_path / "out" / "status.csv")}
    assert status["missing"].startswith("failed: invalid case: ") and "file not found" in status["missing"]
    assert "must be in (0, 1] (got 5)" in status["beads"]
    assert "starting a local Dask cluster" not in result.output


def test_missing_dask_jobqueue_is_bad_input(tmp_path, monkeypatch):
    path = _sweep_file(tmp_path, f"runs: [{{case: CASE, set: {{{SHORT}}}}}]\n")
    monkeypatch.setitem(sys.modules, "dask_jobqueue", None)  # import fails, installed or not
    result = _invoke(["sweep", path, "--cluster", "slurm", "--out", tmp_path / "out"])
    assert result.exit_code == 2, result.output
    assert "needs dask-jobqueue, which is not installed: pip install dask-jobqueue" in result.output
    assert not (tmp_path / "out" / "status.csv").exists()


def test_error_line_of_a_run():
    assert _error_line("12:00 [pour] started\nError: stage pour: placed only 3\n", 1) == "stage pour: placed only 3"
    assert _error_line("Error: invalid case (1 problem):\n  c.yaml:3: seed: must be >= 0\n", 2) == \
        "invalid case (1 problem): c.yaml:3: seed: must be >= 0"
    assert _error_line("", -9) == "killed by signal SIGKILL"
    assert _error_line("Traceback (most recent call last):\n  ...\nMemoryError\n", 1) == "exit code 1: MemoryError"


def test_a_run_that_crashes_is_one_failed_reply(tmp_path, monkeypatch):
    # Given a run whose process dies by a signal (as a segfault or the OOM killer would end it)
    import demcli.sweep as sweep

    monkeypatch.setattr(sweep, "_CHILD", "import os, signal; os.kill(os.getpid(), signal.SIGKILL)")
    job = {"id": "r", "case": str(BEADS), "out": str(tmp_path / "r"), "overrides": ["seed=1"], "threads": 1,
           "force": False, "resume": False, "metrics": ["settle.dem.kinetic@last"]}
    # When the worker function runs it, Then it reports the failure instead of raising
    reply = sweep._run_one(job)
    assert reply["status"] == "failed" and reply["message"] == "killed by signal SIGKILL"
    assert reply["wall_time"] > 0 and reply["metrics"] == {}
    log = (tmp_path / "r" / "sweep.log").read_text()
    assert log.startswith(f"$ demcli run {BEADS} --out ") and "# exit code -9" in log


# ---- real sweeps ------------------------------------------------------------------------------

def test_sweep_on_a_local_cluster_survives_a_failing_run(tmp_path):
    # Given two seeds of the smoke case and a run that fails at run time (too many particles to place)
    path = _sweep_file(tmp_path, f"""\
metrics: [settle.dem.kinetic@last, settle.dem.contacts@max]
set: {{{SHORT}}}
runs:
  - case: CASE
    seeds: [1, 2]
  - case: CASE
    name: crowded
    set: {{stages.pour.count: 100000}}
""")
    out = tmp_path / "out"
    # When it runs on a local Dask cluster of two workers
    result = _invoke(["sweep", path, "--workers", 2, "--out", out])
    # Then the sweep finishes, exit code 1, and the table marks exactly the failing run
    assert result.exit_code == 1, result.output
    assert "starting a local Dask cluster: 2 worker processes" in result.output
    assert "1 of 3 runs failed" in result.output
    status = {r["run"]: r for r in _rows(out / "status.csv")}
    assert set(status) == {"beads/seed=1", "beads/seed=2", "crowded"}
    assert status["beads/seed=1"]["status"] == "ok" and status["beads/seed=2"]["status"] == "ok"
    assert status["crowded"]["status"].startswith("failed: stage pour: placed only")
    assert all(float(r["wall_time[s]"]) > 0 for r in status.values())
    assert "| crowded | failed: stage pour: placed only" in result.output
    # and the gathered CSV has one row per run: overrides, metrics (as the records hold them), status, time
    rows = {r["run"]: r for r in _rows(out / "sweep.csv")}
    assert len(rows) == 3
    assert list(rows["crowded"]) == ["run", "case", "stages.settle.time.steps", "seed", "stages.pour.count",
                                     "settle.dem.kinetic@last[J]", "settle.dem.contacts@max[1]", "status",
                                     "wall_time[s]"]
    for seed in (1, 2):
        row, folder = rows[f"beads/seed={seed}"], out / "beads" / f"seed={seed}"
        assert row["seed"] == str(seed) and row["stages.settle.time.steps"] == "300"
        assert float(row["settle.dem.kinetic@last[J]"]) == _record(folder, "kinetic[J]")[-1]
        assert float(row["settle.dem.contacts@max[1]"]) == max(_record(folder, "contacts[1]"))
        from demcli.state import read_meta

        meta = read_meta(folder / "01-settle.h5")
        assert meta["seed"] == seed and meta["step"] == 300
    assert rows["beads/seed=1"]["settle.dem.kinetic@last[J]"] != rows["beads/seed=2"]["settle.dem.kinetic@last[J]"]
    assert rows["crowded"]["settle.dem.kinetic@last[J]"] == "" and rows["crowded"]["seed"] == ""
    assert "placed only" in (out / "crowded" / "sweep.log").read_text()


@pytest.fixture
def scheduler():
    """A running Dask cluster (in this process: its worker pid is ours); closed after the test."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        yield cluster.scheduler_address


def test_sweep_on_an_existing_scheduler(tmp_path, scheduler):
    path = _sweep_file(tmp_path, f"""\
metrics: [settle.dem.kinetic]
runs: [{{case: CASE, set: {{{SHORT}}}, seeds: [3]}}]
""")
    out = tmp_path / "out"
    result = _invoke(["sweep", path, "--scheduler", scheduler, "--out", out])
    assert result.exit_code == 0, result.output
    assert f"connecting to the Dask scheduler at {scheduler}" in result.output
    assert "starting a local Dask cluster" not in result.output
    # the run went through that cluster's worker, which lives in this process
    assert f"pid {os.getpid()}\n" in (out / "beads" / "seed=3" / "sweep.log").read_text()
    (row,) = _rows(out / "sweep.csv")
    assert row["status"] == "ok"
    assert float(row["settle.dem.kinetic@last[J]"]) == _record(out / "beads" / "seed=3", "kinetic[J]")[-1]


def test_sweep_through_dask_jobqueue_with_a_stand_in_slurm(tmp_path, monkeypatch):
    """The SLURM route end to end, with sbatch/scancel stand-ins that start the job script here."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    # a job is a process group of its own (setsid): scancel ends all of it, as SLURM does
    (bin_dir / "sbatch").write_text(f'#!/bin/sh\ncp "$1" {tmp_path}/job_$$.sh\n'
                                    f'setsid sh {tmp_path}/job_$$.sh > {tmp_path}/job_$$.log 2>&1 &\n'
                                    'echo "Submitted batch job $!"\n')
    (bin_dir / "scancel").write_text('#!/bin/sh\nfor j in "$@"; do kill -- "-$j" 2>/dev/null; done\nexit 0\n')
    for f in bin_dir.iterdir():
        f.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    path = _sweep_file(tmp_path, f"""\
metrics: [settle.dem.kinetic]
runs: [{{case: CASE, set: {{{SHORT}}}, seeds: [4]}}]
cluster: {{type: slurm, workers: 1, options: {{memory: 1GB, walltime: "00:10:00"}}}}
""")
    result = _invoke(["sweep", path, "--out", tmp_path / "out"])
    assert result.exit_code == 0, result.output
    assert "submitting slurm jobs for 1 Dask worker (SLURMCluster)" in result.output
    (row,) = _rows(tmp_path / "out" / "sweep.csv")
    assert row["status"] == "ok" and row["seed"] == "4"
    assert "#SBATCH --cpus-per-task=1" in next(tmp_path.glob("job_*.sh")).read_text()


def test_shipped_sweeps_validate():
    cases = BEADS.parent.parent
    for path in sorted([*(cases / "sweeps").glob("*.yaml"), *(cases / "validation").glob("*_sweep.yaml")]):
        plan = check_sweep(path, echo=lambda line: None)
        assert plan.runs and not plan.invalid, path


def test_sigterm_stops_a_sweep_like_ctrl_c(tmp_path, wait_for_files):
    # Given a sweep of two long runs on a local cluster, checkpointing at every record (so a
    # checkpoint file shows that a run is stepping)
    path = _sweep_file(tmp_path, """\
metrics: [settle.dem.kinetic@last]
set: {stages.settle.time.steps: 2000000, stages.settle.output.records: 400, stages.settle.output.checkpoint: 1e-9 s,
      stages.settle.output.snapshots: 0}
runs:
  - case: CASE
    seeds: [1, 2]
""")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "demcli", "sweep", str(path), "--workers", "2", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    folders = [out / "beads" / "seed=1", out / "beads" / "seed=2"]
    wait_for_files(proc, [f / "01-settle.ckpt.h5" for f in folders])
    # When the sweep process gets SIGTERM (`kill`, a batch system's time limit)
    proc.terminate()
    _, err = proc.communicate(timeout=180)
    # Then it stops as at Ctrl-C: exit 1, no traceback, the status table written with the runs
    # marked as stopped, and the runs stopped through their checkpoint path
    assert proc.returncode == 1, err
    assert "Traceback" not in err, err
    status = {r["run"]: r["status"] for r in _rows(out / "status.csv")}
    assert set(status) == {"beads/seed=1", "beads/seed=2"} and "ok" not in status.values(), status
    assert not [f for f in folders if (f / "01-settle.h5").exists()]
    # (a run outlives its closed worker long enough to checkpoint: the sweep does not wait for
    # it, so its log line may come a moment after the sweep has exited)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and not all("interrupted at step" in (f / "log.txt").read_text()
                                                  for f in folders):
        time.sleep(0.1)
    assert all("interrupted at step" in (f / "log.txt").read_text() for f in folders)


def test_a_run_started_from_the_folder_holding_the_checkout_imports_the_installed_demcli(tmp_path, monkeypatch):
    """#27 item 13: the folder that holds a checkout named ``demcli`` shadowed the package in
    the runs' child processes (``cannot import name '__version__' from 'demcli'``)."""
    from demcli.sweep import _CHILD, child_command

    (tmp_path / "demcli" / "cases").mkdir(parents=True)  # a checkout's top folder: no __init__.py
    monkeypatch.chdir(tmp_path)
    plain = subprocess.run([sys.executable, "-c", _CHILD, "--version"], capture_output=True, text=True)
    assert plain.returncode != 0 and "__version__" in plain.stderr  # the trap is real here
    proc = subprocess.run(child_command(["--version"]), capture_output=True, text=True)
    assert proc.returncode == 0 and "demcli, version" in proc.stdout, proc.stderr
