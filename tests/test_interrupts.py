"""Signals held during compiled chunks and run between them (demcli.interrupts)."""

import os
import signal

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
