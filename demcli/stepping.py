"""The calls of a stage's stepping loop into the engine, with what every such loop owes its
user: before the first call, a line when numba is about to compile the kernels (and then the
time it took: the first run on a machine waits about a minute, :func:`demcli.progress.compile_notice`),
and each chunk on the thread count the :class:`~demcli.threads.ThreadGovernor` picks.
"""

import time as _time

from demcli.progress import compile_notice
from demcli.threads import ThreadGovernor


class Stepper:
    """``advance(n)`` of ``system`` for the stage of ``ctx`` (a context manager: on leaving,
    the kernels get back the thread count the run asked for)."""

    def __init__(self, ctx, system):
        self.ctx, self.system = ctx, system
        self.notice = compile_notice(system.step_kernel())
        if self.notice:
            ctx.log(self.notice)
        self.t0 = _time.perf_counter()
        self.governor = ThreadGovernor(ctx.runner.threads, ctx.log)

    def advance(self, n):
        """Run ``n`` steps; returns (status, steps done, seconds they took)."""
        self.governor.threads()
        c0 = _time.perf_counter()
        status, done = self.system.advance(n)
        elapsed = _time.perf_counter() - c0
        self.governor.chunk_done(done, elapsed)
        if self.notice:
            self.ctx.log(f"kernels ready after {_time.perf_counter() - self.t0:.0f} s")
            self.notice = None
        return status, done, elapsed

    def close(self):
        """Give the kernels back the thread count the run asked for."""
        self.governor.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
