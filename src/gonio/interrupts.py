"""SIGINT and SIGTERM as a flag: installed first thing by the command line, read by the run engine.

Python delivers a signal by running its handler between two bytecodes of the main thread; a
handler that raises ``KeyboardInterrupt`` can therefore land anywhere, including inside a
library callback that swallows it (JAX's ``_xla_gc_callback`` prints "Exception ignored" and
carries on). So the handler here always *records* the signal in :data:`FLAG` first, and code
that must stop reliably (the acquisition loop, a move waiting to settle) checks the flag rather
than relying on the exception.

Two modes:

* normal (start-up, imports, any command): the handler records the signal and raises
  :class:`gonio.errors.Interrupted` (a ``KeyboardInterrupt``), so a command stops at once; the
  CLI prints one line and exits with 128 + the signal number;
* deferred (:meth:`StopFlag.deferred`, the run engine's loop over configurations): the first
  signal only sets the flag (the engine finishes the configuration in progress and parks); a
  second one also raises, and sets :attr:`StopFlag.count` to 2, which a move polls, so the run
  stops at once even when the exception is swallowed;
* shielded (:meth:`StopFlag.shielded`): signals are only recorded.

The handler does not raise where Python would ignore the exception (a gc callback, ``__del__``,
a weakref callback): it has the signal delivered again a few milliseconds later, and
``sys.unraisablehook`` does the same for an interrupt ignored anywhere else.

:func:`install` is idempotent and imports only the standard library, so that
``gonio/__main__.py`` can call it before anything heavy is imported.
"""

from __future__ import annotations

import _thread
import gc
import signal
import sys
import threading
from contextlib import contextmanager

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopFlag:
    """Signals received (:attr:`count`, last :attr:`signum`) and the handler's mode."""

    def __init__(self) -> None:
        self.count = 0
        self.signum = 0
        self.defer = False
        self.shield = False
        self.installed = False
        self._redeliver = False

    @property
    def requested(self) -> bool:
        """A stop was asked for (at least one signal since the last :meth:`reset`)."""
        return self.count > 0

    def reset(self) -> None:
        self.count = 0
        self.signum = 0

    def message(self) -> str:
        name = signal.Signals(self.signum).name if self.signum else "signal"
        return f"interrupted ({name})"

    def interrupted(self):
        """The exception to raise for the signals recorded so far."""
        from gonio.errors import Interrupted

        return Interrupted(self.message(), self.signum or signal.SIGINT)

    def handler(self, signum, frame) -> None:
        if self._redeliver:
            self._redeliver = False  # the same signal, delivered again (below)
        else:
            self.count += 1
            self.signum = signum
        if self.shield or (self.defer and self.count == 1):
            return
        if _swallowing(frame):
            # raising here would be printed as "Exception ignored" and lost
            self.redeliver()
            return
        raise self.interrupted()

    def redeliver(self) -> None:
        """Have the last signal delivered again shortly, from another thread (from a handler
        it would re-enter the handler before the code that would swallow it has returned)."""
        self._redeliver = True
        threading.Timer(0.002, _thread.interrupt_main, (self.signum or signal.SIGINT,)).start()

    @contextmanager
    def deferred(self):
        """Within the block the first signal only sets the flag and a second one raises (see
        the module docstring), also inside a :meth:`shielded` block."""
        old = self.defer, self.shield
        self.defer, self.shield = True, False
        try:
            yield self
        finally:
            self.defer, self.shield = old

    @contextmanager
    def shielded(self):
        """Within the block signals are only recorded, never raised: code in it checks
        :attr:`requested` at points where stopping is safe. (An exception raised by a handler
        lands at any bytecode: inside an import of a native module it can abort the
        interpreter, and half-way through a bus transaction it would leave the port busy.)"""
        old = self.shield
        self.shield = True
        try:
            yield self
        finally:
            self.shield = old


def _swallowing(frame) -> bool:
    """Whether ``frame`` runs inside code whose exceptions Python ignores: a garbage-collector
    callback (JAX registers one), a ``__del__`` method or a weakref callback. (Any other such
    place is caught by :func:`_unraisable`.)"""
    codes = {getattr(cb, "__code__", None) for cb in gc.callbacks}
    for _ in range(64):
        if frame is None:
            return False
        code = frame.f_code
        if code in codes or code.co_name == "__del__" or code.co_filename.endswith("weakref.py"):
            return True
        frame = frame.f_back
    return False


_previous_unraisable = None


def _unraisable(unraisable) -> None:
    """``sys.unraisablehook``: an interrupt Python is about to ignore is delivered again."""
    from gonio.errors import Interrupted

    if isinstance(unraisable.exc_value, Interrupted):
        FLAG.redeliver()
        return
    (_previous_unraisable or sys.__unraisablehook__)(unraisable)


#: The process's flag (one per process: signal handlers are process-wide).
FLAG = StopFlag()


def install(early: list[int] | None = None, hold: bool = False) -> StopFlag:
    """Route SIGINT and SIGTERM to :data:`FLAG` (main thread only; otherwise a no-op).

    ``early``: signal numbers recorded before this module could be imported (by
    ``gonio/__main__.py``); they count as received. ``hold``: only record signals until
    someone clears :attr:`StopFlag.shield` (:func:`gonio.cli.main` does, inside the block that
    turns an interrupt into one line).
    """
    global _previous_unraisable
    FLAG.shield = FLAG.shield or hold
    if not FLAG.installed and threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, FLAG.handler)
        if sys.unraisablehook is not _unraisable:
            _previous_unraisable = sys.unraisablehook
            sys.unraisablehook = _unraisable
        FLAG.installed = True
    for signum in early or ():
        FLAG.count += 1
        FLAG.signum = signum
    return FLAG


@contextmanager
def installed(hold: bool = False):
    """:func:`install` for the duration of the block when no one has yet (library use, or
    :func:`gonio.cli.main` called in-process: the previous handlers come back, and the signals
    recorded are forgotten, at the end). ``hold`` as for :func:`install`."""
    if FLAG.installed or threading.current_thread() is not threading.main_thread():
        FLAG.shield = FLAG.shield or hold
        yield FLAG
        return
    old = {sig: signal.getsignal(sig) for sig in SIGNALS}
    install(hold=hold)
    try:
        yield FLAG
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
        if sys.unraisablehook is _unraisable:
            sys.unraisablehook = _previous_unraisable or sys.__unraisablehook__
        FLAG.installed = False
        FLAG.shield = FLAG.defer = False
        FLAG.reset()
