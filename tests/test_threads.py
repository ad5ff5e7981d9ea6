"""The thread governor: a stepping loop never runs slower than one thread (#27 item 17)."""

import numba
import pytest

from demcli import run_case
from demcli.threads import ThreadGovernor


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _run(gov, clock, per_step, chunks, steps=100):
    """Feed ``chunks`` chunks whose cost per step is ``per_step[n]`` on n threads; returns the
    thread counts used."""
    used = []
    for _ in range(chunks):
        n = gov.threads()
        used.append(n)
        seconds = per_step[n] * steps
        clock.t += seconds
        gov.chunk_done(steps, seconds)
    return used


@pytest.fixture
def restore_threads():
    n = numba.get_num_threads()
    yield
    numba.set_num_threads(n)


def test_falls_back_to_one_thread_when_another_program_takes_a_core(restore_threads):
    clock, lines = _Clock(), []
    gov = ThreadGovernor(2, lines.append, probe_every=30.0, clock=clock)
    # Given two threads running at 1.7 x one thread's speed
    used = _run(gov, clock, {1: 1e-3, 2: 1e-3 / 1.7}, 50)
    assert set(used[:10]) == {2}
    # When another program takes a core (two threads collapse 20 x)
    used = _run(gov, clock, {1: 1.1e-3, 2: 20e-3}, 5)
    # Then after one slow chunk and one probe it runs on one thread, and says so
    assert used[:3] == [2, 1, 1] and set(used[2:]) == {1}
    assert len(lines) == 1 and "1 instead of 2" in lines[0] and "another program" in lines[0]
    # and when the core is free again, a later probe brings the second thread back
    used = _run(gov, clock, {1: 1e-3, 2: 1e-3 / 1.7}, 400)
    assert used[-1] == 2 and "2 instead of 1" in lines[-1] and "free again" in lines[-1]


def test_probes_cost_one_chunk_per_interval_and_keep_the_faster_count(restore_threads):
    clock, lines = _Clock(), []
    gov = ThreadGovernor(2, lines.append, probe_every=30.0, clock=clock)
    # Given healthy two threads (0.1 s chunks), over 10 minutes
    used = _run(gov, clock, {1: 1e-3, 2: 1e-3 / 1.7}, 10000)
    # Then one chunk in about 30 s of them runs on one thread, and it never switches
    probes = used.count(1)
    assert 15 <= probes <= 25 and lines == []


def test_steps_growing_dearer_do_not_make_it_probe_at_every_chunk(restore_threads):
    """A settling bed's steps cost more as contacts form (here 4 x over the run): that is no
    reason to probe; only the periodic probes run on one thread, and it keeps two."""
    clock, lines = _Clock(), []
    gov = ThreadGovernor(2, lines.append, probe_every=30.0, clock=clock)
    used = []
    for k in range(2000):
        grow = 1.0 + 3.0 * k / 2000
        used += _run(gov, clock, {1: 1e-3 * grow, 2: 1e-3 / 1.7 * grow}, 1)
    assert used.count(1) < 0.01 * len(used) and lines == []


def test_one_thread_asked_is_left_alone(restore_threads):
    clock, lines = _Clock(), []
    gov = ThreadGovernor(1, lines.append, probe_every=0.0, clock=clock)
    assert set(_run(gov, clock, {1: 1e-3}, 20)) == {1} and lines == []


def test_switching_threads_mid_stage_keeps_the_result_bit_identical(smoke_case, tmp_path, monkeypatch, h5_differences,
                                                                    restore_threads):
    # Given a reference run on one thread
    run_case(smoke_case, out=tmp_path / "one", quiet=True, threads=1)
    # When a two-thread run probes one thread at every chunk (and switches as timing says)
    monkeypatch.setattr(ThreadGovernor, "PROBE_EVERY", 0.0)
    used = []
    real = ThreadGovernor.threads
    monkeypatch.setattr(ThreadGovernor, "threads", lambda self: used.append(real(self)) or used[-1])
    run_case(smoke_case, out=tmp_path / "mixed", quiet=True, threads=2)
    # Then both counts ran chunks, and the state is the one-thread state bit for bit
    assert {1, 2} <= set(used)
    assert h5_differences(tmp_path / "one" / "01-settle.h5", tmp_path / "mixed" / "01-settle.h5") == []
