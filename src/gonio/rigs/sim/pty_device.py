"""A device emulator that owns the master side of a pseudo-terminal and answers in a thread.

The driver under test opens the slave path exactly as it opens a USB adapter (``/dev/ttyUSB0``,
``/dev/ttyACM0``), so the code path is the hardware one. Subclasses implement :meth:`_serve`,
which runs until ``self._stop`` is set, reading from and writing to ``self._master``.
"""

from __future__ import annotations

import os
import threading
import tty
from typing import Self


class PtyDevice:
    """Base of the servo-bus and LED-driver emulators: pty lifetime and the serving thread."""

    #: Name of the serving thread (shown in debuggers and thread dumps).
    thread_name = "pty-device"

    def __init__(self) -> None:
        self.port = ""
        self._master = -1
        self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _serve(self) -> None:
        raise NotImplementedError

    def start(self) -> str:
        """Open the pty, start answering, and return the slave path for the driver."""
        self._master, self._slave = os.openpty()
        # Raw mode: no echo, no newline translation; pyserial sets it again when it opens.
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name=self.thread_name, daemon=True)
        self._thread.start()
        return self.port

    def stop(self) -> None:
        """Stop the thread and close the pty."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
