"""The staged pipeline: outputs, skipping, determinism, resume, guards, only-declared effects."""

import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest

from demcli import run_case
from demcli.errors import StageError

SMOKE = Path(__file__).resolve().parent.parent / "cases" / "smoke" / "beads.yaml"  # the smoke_case fixture's file


def test_run_writes_states_snapshots_records(smoke_case, tmp_path):
    # Given the smoke case
    # When run
    res = run_case(smoke_case, out=tmp_path, quiet=True)
    # Then every stage wrote its state, the dem stage its VTU series and records
    assert [r.name for r in res] == ["pour", "settle"] and not any(r.skipped for r in res)
    assert (tmp_path / "00-pour.h5").exists() and (tmp_path / "01-settle.h5").exists()
    assert (tmp_path / "settle" / "spheres.pvd").exists()
    assert (tmp_path / "records" / "settle_dem.csv").read_text().startswith("time[s],")
    # and the snapshots carry the fields ParaView colours by
    mesh = meshio.read(tmp_path / "settle" / "spheres_000001.vtu")
    for name in ("radius", "velocity", "body_id", "material"):
        assert name in mesh.point_data
    assert len(mesh.points) == 150
    assert np.all(mesh.point_data["radius"] >= 1e-3 - 1e-12)


def test_unchanged_stages_are_skipped_and_edits_rerun(smoke_case, tmp_path):
    # Given a finished run
    run_case(smoke_case, out=tmp_path, quiet=True)
    # When run again unchanged, then nothing re-runs
    assert all(r.skipped for r in run_case(smoke_case, out=tmp_path, quiet=True))
    # When the second stage's config changes, only it re-runs
    res = run_case(smoke_case, out=tmp_path, quiet=True, overrides=["stages.settle.time.steps=2000"])
    assert [r.skipped for r in res] == [True, False]
    # When --force is given, both re-run
    assert not any(r.skipped for r in run_case(smoke_case, out=tmp_path, quiet=True, force=True,
                                                 overrides=["stages.settle.time.steps=2000"]))


def test_same_case_and_seed_bit_identical_for_1_and_2_threads(smoke_case, tmp_path, h5_differences):
    # Given the same case run with 1 thread and with 2 threads
    run_case(smoke_case, out=tmp_path / "a", quiet=True, threads=1)
    run_case(smoke_case, out=tmp_path / "b", quiet=True, threads=2)
    # Then every dataset of every state is bit-identical
    for name in ("00-pour.h5", "01-settle.h5"):
        assert h5_differences(tmp_path / "a" / name, tmp_path / "b" / name) == []


def test_other_seed_differs(smoke_case, tmp_path, h5_datasets):
    run_case(smoke_case, out=tmp_path / "a", quiet=True, only=None)
    run_case(smoke_case, out=tmp_path / "b", quiet=True, overrides=["seed=8"])
    xa = h5_datasets(tmp_path / "a" / "00-pour.h5")["bodies/x"]
    xb = h5_datasets(tmp_path / "b" / "00-pour.h5")["bodies/x"]
    assert not np.array_equal(xa, xb)


def _raise_at_chunk(monkeypatch, exc, k):
    """Make the k-th System.advance call (a chunk of the dem stage) raise ``exc``; returns
    a function that puts the real advance back."""
    from demcli.engine import system as system_mod

    real = system_mod.System.advance
    calls = {"n": 0}

    def advance(self, n):
        calls["n"] += 1
        if calls["n"] == k:
            raise exc
        return real(self, n)

    monkeypatch.setattr(system_mod.System, "advance", advance)
    return lambda: monkeypatch.setattr(system_mod.System, "advance", real)


@pytest.mark.parametrize("records, k", [(20, 12), (2, 3)])  # (2, 3): before the first record after step 0
def test_interrupted_and_resumed_equals_uninterrupted(smoke_case, tmp_path, monkeypatch, h5_differences, records, k):
    # Given an uninterrupted reference run
    overrides = [f"stages.settle.output.records={records}"]
    run_case(smoke_case, out=tmp_path / "ref", quiet=True, overrides=overrides)
    # When a run is interrupted (Ctrl-C) in the middle of the dem stage
    restore = _raise_at_chunk(monkeypatch, KeyboardInterrupt, k)
    with pytest.raises(StageError, match=f"interrupted at step {0 if records == 2 else ''}"):
        run_case(smoke_case, out=tmp_path / "run", quiet=True, overrides=overrides)
    assert (tmp_path / "run" / "01-settle.ckpt.h5").exists()
    assert not (tmp_path / "run" / "01-settle.h5").exists()
    # and resumed
    restore()
    res = run_case(smoke_case, out=tmp_path / "run", quiet=True, resume=True, overrides=overrides)
    # Then the first stage is skipped, the checkpoint is gone, and the result is bit-identical
    assert [r.skipped for r in res] == [True, False]
    assert not (tmp_path / "run" / "01-settle.ckpt.h5").exists()
    assert h5_differences(tmp_path / "ref" / "01-settle.h5", tmp_path / "run" / "01-settle.h5") == []


def test_a_stage_continues_elsewhere_from_its_input_and_checkpoint_alone(smoke_case, tmp_path, monkeypatch,
                                                                         h5_differences):
    # Given an uninterrupted reference run and a run interrupted in its second stage
    run_case(smoke_case, out=tmp_path / "ref", quiet=True)
    restore = _raise_at_chunk(monkeypatch, KeyboardInterrupt, 12)
    with pytest.raises(StageError, match="interrupted at step"):
        run_case(smoke_case, out=tmp_path / "run", quiet=True)
    restore()
    # When only the stage's input state and its checkpoint are carried to a new folder (another
    # machine, a later batch job) and the run goes on from that stage
    moved = tmp_path / "moved"
    moved.mkdir()
    for name in ("00-pour.h5", "01-settle.ckpt.h5"):
        shutil.copy2(tmp_path / "run" / name, moved / name)
    res = run_case(smoke_case, out=moved, quiet=True, resume=True, from_stage="settle")
    # Then it continued from the checkpoint (gone now) to the uninterrupted result, bit for bit
    assert [r.name for r in res] == ["settle"]
    assert "[settle] resuming from 01-settle.ckpt.h5 at step" in (moved / "log.txt").read_text()
    assert not (moved / "01-settle.ckpt.h5").exists()
    assert h5_differences(tmp_path / "ref" / "01-settle.h5", moved / "01-settle.h5") == []


class _Crash(BaseException):
    """A hard stop (power cut, kill -9, a job's time limit without a signal): nothing is written."""


def test_periodic_checkpoint_survives_a_hard_stop(smoke_case, tmp_path, monkeypatch, h5_differences):
    # Given an uninterrupted reference run
    run_case(smoke_case, out=tmp_path / "ref", quiet=True)
    # When a run that checkpoints at every record (any wall-clock interval elapses) dies mid-stage
    # without the chance to write anything
    every = ["stages.settle.output.checkpoint=1e-9 s"]
    restore = _raise_at_chunk(monkeypatch, _Crash, 12)
    with pytest.raises(_Crash):
        run_case(smoke_case, out=tmp_path / "run", quiet=True, overrides=every)
    # Then the last periodic checkpoint is there, from a step before the crash
    ckpt = tmp_path / "run" / "01-settle.ckpt.h5"
    with h5py.File(ckpt, "r") as f:
        assert 0 < f["meta"].attrs["step"] < 3000
    # and resuming from it gives the uninterrupted result, bit for bit, and removes it
    restore()
    res = run_case(smoke_case, out=tmp_path / "run", quiet=True, resume=True, overrides=every)
    assert [r.skipped for r in res] == [True, False]
    assert not ckpt.exists()
    assert h5_differences(tmp_path / "ref" / "01-settle.h5", tmp_path / "run" / "01-settle.h5") == []


_LONG = ["--set", "stages.settle.time.steps=100000", "--set", "stages.settle.output.records=2",
         "--set", "stages.settle.output.snapshots=0"]  # chunks of ~0.5 s (a record every 50 000 steps)
_LONG_OVERRIDES = [v for v in _LONG if v != "--set"]  # the same, as run_case takes them


@pytest.fixture(scope="module")
def long_reference(tmp_path_factory):
    """The uninterrupted long run of the sphere smoke case (the smoke_case fixture's file),
    shared by the signal tests."""
    out = tmp_path_factory.mktemp("long_reference")
    run_case(SMOKE, out=out, quiet=True, overrides=_LONG_OVERRIDES)
    return out / "01-settle.h5"


@pytest.mark.parametrize("sig, when", [("SIGTERM", "between"), ("SIGTERM", "during"), ("SIGINT", "during")])
def test_signal_writes_a_checkpoint(smoke_case, tmp_path, h5_differences, long_reference, sig, when):
    # Given an uninterrupted reference run (long_reference)
    # When `demcli run` gets SIGTERM (a batch system's time limit) or SIGINT (Ctrl-C) in the middle
    # of the dem stage: between two chunks, or while a compiled chunk runs (a process outside
    # sends it 0.1 s into a chunk of ~0.5 s: the stage sizes its chunks to half a second)
    script = f"""
import os, signal, subprocess, sys, time
from demcli.engine import system as system_mod
from demcli.cli import main
signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (a background job ignores SIGINT)
real = system_mod.System.advance
calls = [0]
def advance(self, n):
    calls[0] += 1
    if calls[0] != 3:
        return real(self, n)
    if {when!r} == "between":
        os.kill(os.getpid(), signal.{sig})
        return real(self, n)
    killer = subprocess.Popen(["sh", "-c", "sleep 0.1; kill -{sig[3:]} {{}}".format(os.getpid())])
    t0 = time.perf_counter()
    out = real(self, n)
    if killer.poll() is not None and time.perf_counter() - t0 > 0.1:
        print("signal arrived during the chunk", file=sys.stderr)
    killer.wait()
    return out
system_mod.System.advance = advance
main(["run", {str(smoke_case)!r}, "--out", {str(tmp_path / "run")!r}, "--quiet", "--threads", "1", *{_LONG!r}])
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    # Then (the signal having come when meant) it stops with a message, no traceback, and
    # leaves the checkpoint
    if when == "during":
        assert "signal arrived during the chunk" in proc.stderr
    assert proc.returncode != 0
    assert "interrupted" in proc.stderr and "--resume" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert (tmp_path / "run" / "01-settle.ckpt.h5").exists()
    # and --resume finishes it bit-identically
    run_case(smoke_case, out=tmp_path / "run", quiet=True, resume=True, overrides=_LONG_OVERRIDES)
    assert h5_differences(long_reference, tmp_path / "run" / "01-settle.h5") == []


def _poison(path, fn):
    """Change a state file through the state API (a file edited in place fails its checksums)."""
    from demcli.state import read_state, write_state

    st = read_state(path)
    fn(st)
    write_state(path, st)


@pytest.mark.parametrize("poison, message", [
    # finite velocities whose sum overflows (a NaN in a state file is refused when it is read)
    (lambda st: st["bodies/v"].__setitem__(3, [1e308, 1e308, 0.0]), "NaN or Inf"),
    (lambda st: st["bodies/x"].__setitem__(1, st["bodies/x"][0] + [1.0e-4, 0, 0]), "overlap beyond the limit"),
])
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_guards_stop_with_diagnosis_and_keep_last_good_state(smoke_case, tmp_path, poison, message, h5_datasets):
    # Given a first-stage state with an injected defect
    run_case(smoke_case, out=tmp_path, quiet=True, only=None, overrides=["stages.settle.time.steps=10"])
    _poison(tmp_path / "00-pour.h5", poison)
    # When the dem stage runs on it
    with pytest.raises(StageError) as err:
        run_case(smoke_case, out=tmp_path, quiet=True, only="settle")
    # Then it stops with a diagnosis naming the guard and the time step, and keeps the last good state
    text = str(err.value)
    assert message in text and "critical" in text and "01-settle.lastgood.h5" in text
    good = h5_datasets(tmp_path / "01-settle.lastgood.h5")
    assert np.isfinite(good["bodies/x"]).all() if "NaN" not in message else True


def test_runaway_energy_guard(smoke_case, tmp_path):
    # Given a time step four times the critical one (allowed explicitly for this test)
    over = ["stages.settle.time.dt=1e-4", "stages.settle.safety.allow_unstable_dt=true",
            "stages.settle.safety.check_every=10"]
    # When run
    with pytest.raises(StageError) as err:
        run_case(smoke_case, out=tmp_path, quiet=True, overrides=over)
    # Then a guard stops it (energy, overlap or NaN, whichever trips first) and says the step is too large
    text = str(err.value)
    assert "stopped at step" in text and "of the critical" in text
    assert (tmp_path / "01-settle.lastgood.h5").exists()


def test_cli_exit_code_1_on_instability(smoke_case, tmp_path):
    # Given the same unstable run through the command line
    cmd = [sys.executable, "-m", "demcli", "run", str(smoke_case), "--out", str(tmp_path), "--quiet",
           "--set", "stages.settle.time.dt=1e-4", "--set", "stages.settle.safety.allow_unstable_dt=true"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    # Then exit code 1, a message, no traceback
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "last good state kept in" in proc.stderr


def test_undeclared_effects_allocate_nothing_and_run_no_pass(tmp_path):
    # Given a scene that declares only gravity
    from demcli.engine.materials import ContactModel, Material
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System, Walls
    from demcli.kernels import layout as K

    n = 20
    x = np.stack([np.arange(n) * 1.9e-3, np.zeros(n), np.zeros(n)], axis=1)  # overlapping chain
    groups = {"bodies": {"x": x, "v": np.zeros((n, 3)), "omega": np.zeros((n, 3)),
                         "q": np.tile([1.0, 0, 0, 0], (n, 1)), "mass": np.full(n, 1e-5),
                         "inertia": np.full((n, 3), 4e-12), "flags": np.zeros(n, np.int8), "id": np.arange(n)},
              "spheres": {"body": np.arange(n), "offset": np.zeros((n, 3)), "radius": np.full(n, 1e-3),
                          "material": np.zeros(n, np.int64)}}
    plan = make_plan(["gravity"])
    s = System(groups, [Material("m", 2500.0, young=1e7)], ContactModel(), plan, Walls(), Dynamics(), dt=1e-7)
    s.advance(50)
    nl = s.nl
    # Then friction, rolling and energy arrays have no rows although contacts exist
    assert nl.act.sum() > 0
    assert nl.ft.shape[0] == 0 and nl.mr.shape[0] == 0 and nl.epair.shape[0] == 0
    assert nl.tj.shape[0] == 0  # no torque rows
    assert s.esph.shape[0] == 0 and s.ebody.shape[0] == 0 and len(s.L) == 0
    # and the kernel never entered their passes, while the declared ones ran every step
    c = dict(zip(K.COUNTERS, s.counters))
    assert c["friction"] == c["rolling"] == c["energy"] == c["damping"] == 0
    assert c["members"] == c["body"] == c["wallmove"] == c["wallctrl"] == 0
    assert c["kick"] == 50
    assert c["gravity"] == c["pairs"] == c["gather"] == 51  # + the priming evaluation of F(x_0)
    # and the plan lists no pass or array for them
    assert not any(p.startswith(("pairs:tangential", "pairs:rolling", "walls:")) for p in plan.passes)
    assert not any(f[0] in ("contact_ft", "contact_mr", "pair_losses") for f in plan.fields)


def test_progress_in_a_log_every_tenth_and_every_minute(capsys, monkeypatch):
    # Given progress written to a log (not a terminal) over 1000 steps
    from demcli import pipeline

    clock = {"t": 0.0}
    monkeypatch.setattr(pipeline._time, "perf_counter", lambda: clock["t"])
    p = pipeline.Progress("settle", 1000, 0, False, 10)
    # When steps come slowly (1 step per 10 s: 10 % takes 1000 s)
    for step in range(1, 30):
        clock["t"] = 10.0 * step
        p.update(step)
    lines = capsys.readouterr().err.splitlines()
    # Then a line comes every LOG_EVERY (60 s) though no 10 % mark is passed, with rate and ETA
    assert len(lines) == 29 * 10 // 60
    assert "step 6/1000" in lines[0] and "particle-steps/s" in lines[0] and "ETA" in lines[0]
    # and every 10 % when steps come fast
    p = pipeline.Progress("settle", 1000, 0, False, 10)
    for step in range(1, 1001):
        clock["t"] += 1e-3
        p.update(step)
    assert len(capsys.readouterr().err.splitlines()) == 10
