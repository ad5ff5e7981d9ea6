"""Signals held during compiled chunks and run between them (demcli.interrupts)."""

import os
import signal
import time

import pytest

from demcli import interrupts


@pytest.fixture
def recording_handler():
    """SIGTERM's handler appends to a list (restored afterwards)."""
    seen = []
    old = signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    yield seen
    signal.signal(signal.SIGTERM, old)


def test_signal_waits_for_poll(recording_handler):
    # Given a block that holds signals
    with interrupts.deferred() as poll:
        # When SIGTERM arrives inside it
        os.kill(os.getpid(), signal.SIGTERM)
        # Then the handler has not run yet, and runs at the poll, once
        assert recording_handler == []
        poll()
        assert recording_handler == [signal.SIGTERM]
        poll()
    assert recording_handler == [signal.SIGTERM]


def test_held_signal_runs_on_leaving_and_handlers_come_back(recording_handler):
    handler = signal.getsignal(signal.SIGTERM)
    # When a signal is still held when the block ends
    with interrupts.deferred():
        assert signal.getsignal(signal.SIGTERM) is not handler
        os.kill(os.getpid(), signal.SIGTERM)
    # Then its handler ran on leaving, and the handler is back
    assert recording_handler == [signal.SIGTERM]
    assert signal.getsignal(signal.SIGTERM) is handler


def test_ctrl_c_raises_at_the_poll():
    # Given Python's own Ctrl-C handler
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with interrupts.deferred() as poll:
            os.kill(os.getpid(), signal.SIGINT)  # no exception here
            # Then KeyboardInterrupt comes from the poll
            with pytest.raises(KeyboardInterrupt):
                poll()
    finally:
        signal.signal(signal.SIGINT, old)


def test_an_exception_in_the_block_drops_held_signals(recording_handler):
    with pytest.raises(RuntimeError):
        with interrupts.deferred():
            os.kill(os.getpid(), signal.SIGTERM)
            raise RuntimeError("stage failed")
    assert recording_handler == []


def test_held_signals_can_be_dropped_on_leaving(recording_handler):
    # Given a block that must not be cut short and whose caller is already stopping
    with interrupts.deferred(keep=False):
        os.kill(os.getpid(), signal.SIGTERM)
    # Then the signal neither cut it short nor runs afterwards, and the handler is back
    assert recording_handler == []
    os.kill(os.getpid(), signal.SIGTERM)
    assert recording_handler == [signal.SIGTERM]


def test_a_second_ctrl_c_while_the_checkpoint_is_written_does_not_cut_it_short(tmp_path, monkeypatch):
    """Ctrl-C stops a stage; a second one (or a batch system's SIGTERM) arriving while the
    stage writes its checkpoint waits for the write: the checkpoint is whole and readable,
    the stage reports its interruption, and it resumes."""
    from pathlib import Path

    from demcli import run_case
    from demcli.engine.system import System
    from demcli.errors import StageError
    from demcli.pipeline import StageContext
    from demcli.state import read_state

    case = Path(__file__).resolve().parent.parent / "cases" / "smoke" / "beads.yaml"
    real_advance, real_write = System.advance, StageContext.write_checkpoint

    def advance(self, n):
        if self.step >= 600:
            raise KeyboardInterrupt
        return real_advance(self, n)

    def write(self, state):
        os.kill(os.getpid(), signal.SIGINT)  # the second Ctrl-C, in the middle of the write
        return real_write(self, state)

    monkeypatch.setattr(System, "advance", advance)
    monkeypatch.setattr(StageContext, "write_checkpoint", write)
    with pytest.raises(StageError, match="interrupted at step 600"):
        run_case(case, out=tmp_path, quiet=True)
    assert read_state(tmp_path / "01-settle.ckpt.h5").meta["step"] == 600
    assert not list(tmp_path.glob(".*.tmp-*"))  # no half-written file left
    monkeypatch.setattr(System, "advance", real_advance)
    monkeypatch.setattr(StageContext, "write_checkpoint", real_write)
    run_case(case, out=tmp_path, quiet=True, resume=True)
    assert (tmp_path / "01-settle.h5").exists()


def _frame_in(filename):
    """A frame whose code comes from ``filename``."""
    ns = {}
    exec(compile("import sys\nframe = sys._getframe()", filename, "exec"), ns)
    return ns["frame"]


def test_a_signal_inside_llvmlite_is_sent_again_later(monkeypatch):
    # Given the stop handler and a frame inside llvmlite (numba compiling: a ctypes callback,
    # where an exception would be printed and dropped)
    sent = []
    monkeypatch.setattr(interrupts.os, "kill", lambda pid, sig: sent.append((pid, sig)))
    frame = _frame_in(os.path.join(os.sep, "site-packages", "llvmlite", "binding", "executionengine.py"))
    # When SIGTERM lands there
    interrupts._raise_interrupt(signal.SIGTERM, frame)
    # Then nothing is raised, and the same signal goes to this process again a moment later
    assert sent == []
    deadline = time.monotonic() + 5
    while not sent and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sent == [(os.getpid(), signal.SIGTERM)]
    # while anywhere else it is a KeyboardInterrupt at once
    with pytest.raises(KeyboardInterrupt):
        interrupts._raise_interrupt(signal.SIGTERM, _frame_in(os.path.join(os.sep, "work", "demcli", "x.py")))


def test_stop_as_interrupt_takes_sigterm_and_leaves_an_ignored_sigint(monkeypatch):
    # Given SIGINT ignored (a background job) and SIGTERM at its default
    old = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        # When the stop handlers go in
        saved = interrupts.stop_as_interrupt()
        # Then SIGTERM raises KeyboardInterrupt, SIGINT stays ignored, and restore() puts back SIGTERM
        assert signal.getsignal(signal.SIGTERM) is interrupts._raise_interrupt
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)
        interrupts.restore(saved)
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
