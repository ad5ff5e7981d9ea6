"""Ctrl-C / SIGTERM at any point of a stage: stepping, its last chunk, its output writes, the
state write; the run stops with a message and the resumed run equals the uninterrupted one
bit for bit (states, records and snapshot series)."""

import os
import signal
from pathlib import Path

import pytest

from demcli import run_case
from demcli.errors import StageError

ROOT = Path(__file__).resolve().parents[2]
SPHERES = "cases/smoke/beads.yaml"          # 3 000 steps, a record every 150
POLYHEDRA = "cases/smoke/ballast_deposit.yaml"  # 9 000 steps, a record every 450


@pytest.fixture(autouse=True)
def ctrl_c_raises(monkeypatch):
    """SIGINT raises KeyboardInterrupt, as in a terminal."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Uninterrupted runs of the two smoke cases, made once."""
    out = {}
    for case in (SPHERES, POLYHEDRA):
        folder = tmp_path_factory.mktemp("ref")
        run_case(ROOT / case, out=folder, quiet=True)
        out[case] = folder
    return out


def _send_sigint_once(monkeypatch, cls, method, when):
    """After ``cls.method`` returns and ``when(self)`` holds, SIGINT arrives (once)."""
    real = getattr(cls, method)
    sent = []

    def wrapped(self, *args, **kwargs):
        out = real(self, *args, **kwargs)
        if not sent and when(self):
            sent.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        return out

    monkeypatch.setattr(cls, method, wrapped)
    return lambda: monkeypatch.setattr(cls, method, real)


def _same_run(ref, run, h5_differences, stage):
    assert h5_differences(ref / stage, run / stage) == []
    for sub in ("records", stage.split("-", 1)[1].removesuffix(".h5")):
        names = sorted(p.name for p in (ref / sub).iterdir() if p.suffix in (".csv", ".pvd"))
        assert names == sorted(p.name for p in (run / sub).iterdir() if p.suffix in (".csv", ".pvd"))
        for name in names:
            assert (ref / sub / name).read_text() == (run / sub / name).read_text(), name


@pytest.mark.parametrize("case, stage, step", [
    (SPHERES, "01-settle.h5", 1),       # the first chunk
    (SPHERES, "01-settle.h5", 1500),    # a record in the middle
    (SPHERES, "01-settle.h5", 2980),    # a chunk between two records
    (SPHERES, "01-settle.h5", 3000),    # the last chunk (the stage's last step)
    (POLYHEDRA, "03-deposit.h5", 4000),
    (POLYHEDRA, "03-deposit.h5", 9000),
])
def test_interrupted_anywhere_in_the_stepping_resumes_bit_identical(reference, tmp_path, monkeypatch, h5_differences,
                                                                     case, stage, step):
    from demcli.engine.system import System

    # Given Ctrl-C once the stage has stepped to `step`
    restore = _send_sigint_once(monkeypatch, System, "advance", lambda s: s.step >= step)
    with pytest.raises(StageError, match="interrupted at step .*--resume"):
        run_case(ROOT / case, out=tmp_path, quiet=True)
    restore()
    assert (tmp_path / stage.replace(".h5", ".ckpt.h5")).exists()
    # When it resumes
    run_case(ROOT / case, out=tmp_path, quiet=True, resume=True)
    # Then the state (contacts, wall forces...), records and snapshot series are the uninterrupted ones
    _same_run(reference[case], tmp_path, h5_differences, stage)
    assert not (tmp_path / stage.replace(".h5", ".ckpt.h5")).exists()


@pytest.mark.parametrize("overrides", [[], ["stages.settle.stop.kinetic_ratio=1e6", "stages.settle.stop.min_time=0.01 s"]])
def test_interrupted_while_writing_outputs_checkpoints_the_finished_loop(tmp_path, monkeypatch, h5_differences,
                                                                         overrides):
    """Ctrl-C while the stage writes its plots: the finished stepping is checkpointed (also a
    stepping that ended early by its stop criterion), and --resume writes the outputs only."""
    from demcli.state import records

    run_case(ROOT / SPHERES, out=tmp_path / "ref", quiet=True, overrides=overrides)
    restore = _send_sigint_once(monkeypatch, records.RecordTable, "write_csv", lambda s: True)
    with pytest.raises(StageError, match=r"interrupted while writing its outputs .*--resume"):
        run_case(ROOT / SPHERES, out=tmp_path / "run", quiet=True, overrides=overrides)
    restore()
    run_case(ROOT / SPHERES, out=tmp_path / "run", quiet=True, resume=True, overrides=overrides)
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "resuming from 01-settle.ckpt.h5" in log and "] 0 steps in" in log
    _same_run(tmp_path / "ref", tmp_path / "run", h5_differences, "01-settle.h5")


def test_interrupted_in_the_chunk_where_the_stop_criterion_fires(tmp_path, monkeypatch, h5_differences):
    """Ctrl-C in the chunk whose record ends the stepping (here: the first record after 0.01 s,
    by a kinetic ratio nothing fails): --resume does not step past the stop."""
    from demcli.engine.system import System

    stop = ["stages.settle.stop.kinetic_ratio=1e6", "stages.settle.stop.min_time=0.01 s"]
    run_case(ROOT / SPHERES, out=tmp_path / "ref", quiet=True, overrides=stop)
    restore = _send_sigint_once(monkeypatch, System, "advance", lambda s: s.step % 150 == 0 and s.time >= 0.01)
    with pytest.raises(StageError, match="interrupted"):
        run_case(ROOT / SPHERES, out=tmp_path / "run", quiet=True, overrides=stop)
    restore()
    run_case(ROOT / SPHERES, out=tmp_path / "run", quiet=True, resume=True, overrides=stop)
    assert "stopped at rest" in (tmp_path / "ref" / "log.txt").read_text()
    _same_run(tmp_path / "ref", tmp_path / "run", h5_differences, "01-settle.h5")


def test_interrupted_while_the_state_is_written_finishes_the_write(reference, tmp_path, monkeypatch, h5_differences):
    """Ctrl-C during the state write: the write completes, the run stops right after with a
    message, and the next run finds the stage up to date."""
    from demcli.state import h5

    calls = []
    real = h5.write_state

    def write_state(path, state):
        calls.append(path)
        if len(calls) == 2:  # the settle stage's state
            os.kill(os.getpid(), signal.SIGINT)
        return real(path, state)

    monkeypatch.setattr(h5, "write_state", write_state)
    monkeypatch.setattr("demcli.state.write_state", write_state)
    with pytest.raises(StageError, match="interrupted after stage settle finished"):
        run_case(ROOT / SPHERES, out=tmp_path, quiet=True)
    res = run_case(ROOT / SPHERES, out=tmp_path, quiet=True)
    assert [r.skipped for r in res] == [True, True]
    assert h5_differences(reference[SPHERES] / "01-settle.h5", tmp_path / "01-settle.h5") == []
