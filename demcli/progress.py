"""What a long stage tells its user while it runs: progress, throughput and an honest ETA.

:class:`Progress` prints the step, the rate and the ETA; :class:`StopForecast` follows the
quantity a stage's stop criterion watches (the kinetic energy of a bed coming to rest, the
bulk density under a vibrating plate) and predicts the step at which the criterion will end
the stage, so that the ETA is that of the stop and not of the stage's maximum length;
:func:`compile_notice` says, before a stepping loop starts, that numba is about to compile
its kernels (the first run on a machine waits about a minute for it).
"""

import math
import os
import sys
import time as _time

import numpy as np


class Progress:
    """Progress with rate and ETA on stderr: a live line on a terminal, else a line every 10 %
    and at least every ``LOG_EVERY`` seconds (a batch job's log of a long stage).

    ``update(step, end)`` takes the step at which a stop criterion is forecast to end the
    stage (:class:`StopForecast`); the percentage and the ETA then follow that step, and the
    line also gives the ETA of the stage's full length.
    """

    LOG_EVERY = 60.0

    def __init__(self, label, total, start, quiet, nparticles):
        self.label, self.total, self.start, self.quiet, self.np = label, total, start, quiet, nparticles
        self.t0 = _time.perf_counter()
        self.tty = sys.stderr.isatty()
        self.last_print = self.t0
        self.next_pct = 10

    def text(self, step, now, end=None):
        """The progress line at ``step`` (``end``: the forecast last step, or None)."""
        rate = (step - self.start) / max(now - self.t0, 1e-9)
        last = self.total if end is None else max(step, min(int(end), self.total))
        frac = step / last if last > 0 else 1.0
        eta = (last - step) / rate if rate > 0 else math.inf
        out = f"  {self.label}: {100 * frac:5.1f} %  step {step}/{last}"
        if last < self.total:
            out += " (stop criterion, forecast)"
        out += f"  {rate * self.np:.3g} particle-steps/s  ETA {eta:.0f} s"
        if last < self.total:
            out += f" (at most {(self.total - step) / rate if rate > 0 else math.inf:.0f} s)"
        return out, frac

    def update(self, step, end=None):
        """Show progress at ``step`` (``end``: the forecast last step, or None), as the class says."""
        if self.quiet or self.total <= 0:
            return
        now = _time.perf_counter()
        text, frac = self.text(step, now, end)
        if self.tty:
            if now - self.last_print > 0.2:
                sys.stderr.write("\r" + text)
                sys.stderr.flush()
                self.last_print = now
        elif 100 * frac >= self.next_pct or now - self.last_print >= self.LOG_EVERY:
            sys.stderr.write(text + "\n")
            sys.stderr.flush()
            self.last_print = now
            self.next_pct = (int(100 * frac) // 10 + 1) * 10

    def close(self):
        """Clear a terminal's live line."""
        if self.tty and not self.quiet:
            sys.stderr.write("\r" + " " * 120 + "\r")
            sys.stderr.flush()


class StopForecast:
    """The step at which a watched quantity will reach its stop threshold, from its trend.

    ``add(step, value)`` at each record where the stop tests the value; :meth:`end` fits a straight line to the last
    ``window`` values against the step (least squares) and returns where it crosses
    ``target`` (never before ``earliest``, the first step at which the stop may act), or None
    while the trend does not head for the target. ``log=True`` fits log(value) (a kinetic
    energy decaying exponentially). ``rising``: the stop acts when the value reaches the
    target from below (a density), else from above (a kinetic energy).
    """

    def __init__(self, target, rising, log=False, earliest=0, window=6):
        self.log = log
        self.target = math.log(target) if log else float(target)
        self.rising = rising
        self.earliest = int(earliest)
        self.window = window
        self.steps, self.values = [], []

    def add(self, step, value):
        """One record of the watched quantity (None: not tested at this record)."""
        if value is None:
            return
        if self.log:
            if not value > 0:
                return
            value = math.log(value)
        if not math.isfinite(value):
            return
        self.steps.append(float(step))
        self.values.append(float(value))
        del self.steps[:-self.window], self.values[:-self.window]

    def end(self):
        """Forecast step of the stop, or None."""
        if len(self.steps) < 3:
            return None
        slope, icept = np.polyfit(np.asarray(self.steps), np.asarray(self.values), 1)
        if (slope > 0) != self.rising or slope == 0.0:
            return None
        cross = (self.target - icept) / slope
        return max(cross, self.steps[-1], self.earliest)


def compile_notice(dispatcher):
    """A line to log before the first call of a numba ``dispatcher`` that will compile it (none
    compiled in this process, none in numba's cache), else None."""
    if dispatcher.overloads:
        return None
    try:
        cached = dispatcher._cache._cache_file._index_path  # numba's on-disk index of this kernel
    except AttributeError:  # the cache is off (DEMCLI_NUMBA_CACHE=0) or numba changed
        return "compiling kernels (numba's cache is off: ~1 min every run)"
    if os.path.exists(cached):
        return None
    return "compiling kernels (first run on this machine or after an update, ~1 min; cached afterwards)"
