"""Firmware side of the LED driver's line protocol (:mod:`gonio.rigs.lights`) on a pseudo-terminal.

Like the servo-bus emulator, it owns the pty master and answers in a background thread; the
driver (:class:`~gonio.rigs.lights.SerialLEDLight`) opens the slave path through pyserial exactly
as it opens ``/dev/ttyACM0``. Every line received is kept in :attr:`LEDDriverEmulator.received`
so tests can check the commands byte for byte.
"""

from __future__ import annotations

import os
import select
import threading
import tty

from gonio.rigs.lights import LEVEL_MAX

VERSION = "1.0"


class LEDDriverEmulator:
    """An Arduino-style LED driver answering ``ID?``, ``L <n>`` and ``L?``.

    Parameters
    ----------
    silent : never answer (to test the driver's timeout).
    """

    def __init__(self, silent: bool = False) -> None:
        self.level = 0
        self.silent = silent
        self.received: list[bytes] = []
        self.port = ""
        self._master = self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> str:
        """Open the pty, start answering, return the slave path."""
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="led-emulator", daemon=True)
        self._thread.start()
        return self.port

    def stop(self) -> None:
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

    def __enter__(self) -> LEDDriverEmulator:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def reply_to(self, line: bytes) -> bytes:
        """The firmware's answer to one command line (without its newline)."""
        text = line.decode("ascii", "replace").strip()
        if text == "ID?":
            return f"GONIO-LED {VERSION}".encode()
        if text == "L?":
            return f"L {self.level}".encode()
        parts = text.split()
        if len(parts) == 2 and parts[0] == "L":
            if not parts[1].isdigit():
                return b"ERR syntax"
            n = int(parts[1])
            if n > LEVEL_MAX:
                return b"ERR range"
            self.level = n
            return b"OK"
        return b"ERR syntax"

    def _serve(self) -> None:
        buf = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.02)
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 256)
            except OSError:
                return
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                self.received.append(line)
                if not self.silent:
                    os.write(self._master, self.reply_to(line) + b"\n")
