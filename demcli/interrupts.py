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

import os
import signal
import threading
from contextlib import contextmanager

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def deferred(keep=True):
    """Hold SIGINT and SIGTERM inside the block; yields ``poll()``, which runs the held ones.

    Signals still held when the block ends normally run on leaving it (with ``keep=False``
    they are dropped: a block that writes the checkpoint of a stage already stopping, which a
    second Ctrl-C or a batch system's SIGTERM must not cut short); when it ends with an
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
    if keep:
        poll()


_LLVMLITE = f"{os.sep}llvmlite{os.sep}"
RETRY_S = 0.05  # a signal that came inside llvmlite's callbacks is sent again after this [s]


def _inside_llvmlite(frame):
    while frame is not None:
        if _LLVMLITE in frame.f_code.co_filename:
            return True
        frame = frame.f_back
    return False


def _raise_interrupt(signum, frame):
    """KeyboardInterrupt; inside llvmlite (numba compiling or loading a kernel, in a ctypes
    callback, where an exception is printed and dropped) the signal is sent again shortly."""
    if _inside_llvmlite(frame):
        threading.Timer(RETRY_S, os.kill, (os.getpid(), signum)).start()
        return
    raise KeyboardInterrupt


def stop_as_interrupt():
    """SIGTERM (a batch system's time limit, ``kill``) stops this process as Ctrl-C does, and
    neither is lost while numba compiles: a running stage writes its checkpoint. Returns the
    replaced handlers, for :func:`restore` (SIGINT only when Python's default was in place:
    an ignored SIGINT stays ignored)."""
    saved = {}
    for sig in _SIGNALS:
        if sig == signal.SIGTERM or signal.getsignal(sig) is signal.default_int_handler:
            saved[sig] = signal.signal(sig, _raise_interrupt)
    return saved


def restore(saved):
    """Put back the handlers :func:`stop_as_interrupt` replaced."""
    for sig, handler in saved.items():
        signal.signal(sig, handler)
