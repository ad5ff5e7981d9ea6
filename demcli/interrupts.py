"""Ctrl-C and SIGTERM that wait for the end of a compiled chunk.

A Python signal handler runs in the interpreter, never inside numba's compiled code. When
the handler raises (Ctrl-C's ``KeyboardInterrupt``; ``demcli run`` routes SIGTERM there too)
while a compiled function is returning, numba's dispatcher ends with ``SystemError: ...
returned a result with an exception set`` and the stage cannot write its checkpoint.

:func:`deferred` therefore swaps the Python handlers of SIGINT and SIGTERM for one that only
notes the signal, for the length of a stepping loop; the loop calls the ``poll`` function it
yields between chunks, which runs the noted signals' own handlers there, in plain Python, so
that their exception (``KeyboardInterrupt``) reaches the loop's checkpoint path. Signals
whose handler is not a Python callable (the default action, ignored) are left alone.
"""

import signal
import threading
from contextlib import contextmanager

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def deferred():
    """Hold SIGINT and SIGTERM inside the block; yields ``poll()``, which runs the held ones.

    Signals still held when the block ends normally run on leaving it; when it ends with an
    exception they are dropped (the exception already stops the stage). Outside the main
    thread (where Python cannot set handlers) nothing is held and ``poll`` does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    held = []
    saved = {}
    for sig in _SIGNALS:
        handler = signal.getsignal(sig)
        if callable(handler):
            saved[sig] = handler
            signal.signal(sig, lambda signum, frame: held.append(signum))

    def poll():
        while held:
            sig = held.pop(0)
            saved[sig](sig, None)

    try:
        yield poll
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    poll()
