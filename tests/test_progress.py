"""Progress lines: the ETA follows the stop criterion's forecast; the compile notice (#27 item 14)."""

import math

import numpy as np

from demcli.progress import Progress, StopForecast, compile_notice


def test_forecast_of_an_exponential_decay_hits_the_threshold_step():
    # Given a kinetic energy decaying as exp(-step / 1000) and a stop at 1e-3 of its start
    fc = StopForecast(1e-3, rising=False, log=True, earliest=0)
    for step in range(0, 3000, 300):
        fc.add(step, math.exp(-step / 1000.0))
    # Then the forecast is the step where it crosses: 1000 ln(1000)
    assert abs(fc.end() - 1000.0 * math.log(1000.0)) < 1e-6


def test_forecast_waits_for_a_trend_towards_the_target_and_for_the_earliest_stop():
    fc = StopForecast(1.55, rising=True, earliest=40)
    assert fc.end() is None  # no data
    for cycle, rho in enumerate([1.50, 1.49, 1.48, 1.47]):  # loosening: heading away
        fc.add(cycle, rho)
    assert fc.end() is None
    fc = StopForecast(1.55, rising=True, earliest=40)
    for cycle in range(1, 8):
        fc.add(cycle, 1.50 + 0.01 * cycle)  # crosses 1.55 at cycle 5, but the stop acts from 40 on
        fc.add(cycle, None)  # records where the stop tests nothing are ignored
    assert fc.end() == 40


def test_forecast_uses_a_recent_window():
    fc = StopForecast(0.0, rising=False, window=4)
    for step in range(10):
        fc.add(step, 100.0 if step < 6 else 10.0 - step)  # a new trend in the last four points
    assert np.isclose(fc.end(), 10.0)


def test_progress_line_follows_the_forecast_and_gives_the_full_length_too():
    p = Progress("deposit", 10000, 0, True, 100)
    p.t0 = 0.0
    # 1000 steps in 10 s; the stop forecast at step 2000 of at most 10000
    text, frac = p.text(1000, 10.0, end=2000)
    assert "step 1000/2000 (stop criterion, forecast)" in text and "ETA 10 s (at most 90 s)" in text
    assert frac == 0.5
    text, frac = p.text(1000, 10.0)
    assert "step 1000/10000  " in text and "ETA 90 s" in text and "at most" not in text


def test_compile_notice_only_when_nothing_is_compiled_or_cached(tmp_path, monkeypatch):
    import numba

    # Given a kernel compiled in this process: no notice
    @numba.njit(cache=False)
    def f(x):
        return x + 1

    f(1)
    assert compile_notice(f) is None
    # Given one never compiled and without a cache: the notice says so
    @numba.njit(cache=False)
    def g(x):
        return x + 2

    assert "compiling kernels" in compile_notice(g) and "cache is off" in compile_notice(g)


def test_compile_notice_before_the_first_compile_and_none_once_cached(tmp_path, monkeypatch):
    import importlib.util

    import numba

    # Given a kernel module with numba's on-disk cache in a fresh folder
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))
    src = tmp_path / "kern.py"
    src.write_text("import numba\n\n\n@numba.njit(cache=True)\ndef f(x):\n    return x * 2\n")

    def load(name):
        spec = importlib.util.spec_from_file_location(name, src)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod.f

    f = load("kern_a")
    # Then before its first call the notice says it is about to compile
    assert "first run on this machine" in compile_notice(f)
    f(3)  # compiles and writes the cache
    # and a fresh dispatcher of the same kernel (a later run) finds it cached: no notice
    assert compile_notice(load("kern_b")) is None
