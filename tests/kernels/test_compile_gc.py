"""The garbage collector's thresholds while numba compiles (demcli/jit.py, COMPILE_GC_THRESHOLD):
raised from the start of the outermost compile, the caller's restored after it, nested compiles
of callees included."""

import gc

from numba.core import event

from demcli.jit import COMPILE_GC_THRESHOLD, njit


class _Probe(event.Listener):
    """Records the collector's thresholds at the start and end of every compile event."""

    def __init__(self):
        self.seen = []

    def on_start(self, ev):
        self.seen.append(("start", ev.data["dispatcher"].py_func.__name__, gc.get_threshold()))

    def on_end(self, ev):
        self.seen.append(("end", ev.data["dispatcher"].py_func.__name__, gc.get_threshold()))


def test_thresholds_raised_while_compiling_and_restored():
    @njit(cache=False)
    def _inner_gc_probe(x):
        return x + 1.0

    @njit(cache=False)
    def _outer_gc_probe(x):
        return _inner_gc_probe(x) * 2.0

    saved = gc.get_threshold()
    gc.set_threshold(123, 4, 5)
    probe = _Probe()
    try:
        with event.install_listener("numba:compile", probe):
            assert _outer_gc_probe(1.0) == 4.0
        after = gc.get_threshold()
    finally:
        gc.set_threshold(*saved)
    assert after == (123, 4, 5)
    names = [(kind, name) for kind, name, _ in probe.seen]
    assert ("start", "_inner_gc_probe") in names and ("start", "_outer_gc_probe") in names
    # the probe is registered after demcli's listener: every event it sees is inside the raised window,
    # except the outermost end, where demcli's listener (called first) has already restored them
    for kind, name, thr in probe.seen:
        expected = (123, 4, 5) if (kind, name) == ("end", "_outer_gc_probe") else COMPILE_GC_THRESHOLD
        assert thr == expected, (kind, name, thr)
