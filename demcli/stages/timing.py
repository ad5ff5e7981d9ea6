"""The time step of a stage, decided in one place: a pure function of the critical step (from the
scene's groups and materials, :meth:`demcli.engine.system.System.critical_dt`, or a one-sphere
estimate at ``demcli check``) and the stage's ``time`` section.

``time.dt`` [s] is taken as given (refused above the critical step unless
``safety.allow_unstable_dt``); otherwise dt = ``time.dt_factor`` x critical. The number of
steps is ``time.steps`` or ceil(``time.duration`` / dt).
"""

import math

from demcli.errors import InputError


def time_step(dt_crit, dt=None, dt_factor=0.1, allow_unstable=False, where="stage"):
    """The step [s] for a critical step ``dt_crit`` [s]: ``dt`` if given (at most ``dt_crit``
    unless ``allow_unstable``), else ``dt_factor`` x ``dt_crit``."""
    if dt is None:
        return dt_factor * dt_crit
    if dt > dt_crit and not allow_unstable:
        raise InputError(f"{where}: time.dt = {dt:.4g} s is {dt / dt_crit:.3g} times the critical "
                         f"step {dt_crit:.4g} s; lower it or use time.dt_factor")
    return dt


def stage_time_step(cfg, dt_crit, where="stage"):
    """:func:`time_step` with a dem-like stage's ``time`` and ``safety`` sections."""
    safety = cfg.get("safety")
    allow = bool(safety is not None and safety.get("allow_unstable_dt"))
    return time_step(dt_crit, cfg.time.dt, cfg.time.dt_factor, allow, where)


def step_count(timing, dt):
    """Steps of a stage: ``timing.steps``, or ceil(``timing.duration`` / dt)."""
    return timing.steps if timing.steps is not None else int(math.ceil(timing.duration / dt))
