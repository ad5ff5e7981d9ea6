"""Keep a stepping loop at least as fast as one thread when other programs take cores.

OpenMP threads wait for each other at every barrier of a parallel kernel: when another
program takes one of the cores, a two-thread loop can run 20 times slower than one thread
(measured: 5.0e7 -> 2.2e6 particle-steps/s). The start-up choice (:func:`demcli.jit.free_cores`,
from the load average) cannot see a program that starts later, so :class:`ThreadGovernor`
watches the loop: it times every chunk per step and, every ``probe_every`` seconds or at once
when a chunk runs ``slowdown`` times slower per step than the chunk before it, runs one chunk
on the other thread count (one thread, or the asked-for count when it had fallen back),
and keeps whichever was faster. The kernels give bit-identical results for any thread
count, so switching changes nothing but the speed.
"""

import time as _time

import numba


class ThreadGovernor:
    """Chooses the thread count of each chunk of a stepping loop (see the module doc).

    Args:
        threads: the thread count asked for (with 1 the governor does nothing).
        log: ``log(message)`` for each switch.
        probe_every: wall-clock seconds between two probes of the other thread count
            (default ``PROBE_EVERY``).
        slowdown: a chunk slower per step than the one before it by this factor asks for a
            probe now (against the one before, not the best so far: a stage whose steps grow
            dearer as contacts form must not probe at every chunk).
        margin: the other count must be faster by this fraction to switch.
    """

    SKIP = 2  # first chunks not timed (numba loads or compiles the kernels in them)
    PROBE_EVERY = 30.0  # [s], the default of probe_every

    def __init__(self, threads, log, probe_every=None, slowdown=2.0, margin=0.1, clock=_time.perf_counter):
        self.asked = max(1, int(threads))
        self.active = self.asked
        self.log = log
        probe_every = self.PROBE_EVERY if probe_every is None else probe_every
        self.probe_every, self.slowdown, self.margin = probe_every, slowdown, margin
        self.clock = clock
        self.next_probe = clock() + probe_every
        self.recent = {}  # thread count -> seconds per step of its last timed chunk
        self.probing = False
        self.chunks = 0

    def threads(self):
        """Thread count for the next chunk (set in numba as well)."""
        n = self._other() if self.probing else self.active
        if n != numba.get_num_threads():
            numba.set_num_threads(n)
        return n

    def _other(self):
        return 1 if self.active != 1 else self.asked

    def chunk_done(self, steps, seconds):
        """Time of the chunk just run (``steps`` steps in ``seconds``)."""
        self.chunks += 1
        if self.asked == 1 or steps <= 0 or self.chunks <= self.SKIP:
            return
        n = self._other() if self.probing else self.active
        per_step = seconds / steps
        previous = self.recent.get(n, per_step)
        self.recent[n] = per_step
        if self.probing:
            self.probing = False
            self.next_probe = self.clock() + self.probe_every
            if per_step < (1.0 - self.margin) * self.recent.get(self.active, per_step):
                self.log(f"threads: {n} instead of {self.active}: {1.0 / per_step:.4g} steps/s against "
                         f"{1.0 / self.recent[self.active]:.4g}"
                         + (" (another program is using a core)" if n == 1 else " (the cores are free again)"))
                self.active = n
            return
        if self.clock() >= self.next_probe or per_step > self.slowdown * previous:
            self.probing = True

    def close(self):
        """Give the kernels back the thread count asked for."""
        numba.set_num_threads(self.asked)
