"""Firmware side of the LED driver's line protocol (:mod:`gonio.rigs.lights`) on a pseudo-terminal.

Like the servo-bus emulator, it owns the pty master and answers in a background thread; the
driver (:class:`~gonio.rigs.lights.SerialLEDLight`) opens the slave path through pyserial exactly
as it opens ``/dev/ttyACM0``. Every line received is kept in :attr:`LEDDriverEmulator.received`
so tests can check the commands byte for byte.
"""

from __future__ import annotations

import os
import select

from gonio.rigs.lights import LEVEL_MAX
from gonio.rigs.sim.pty_device import PtyDevice

VERSION = "1.0"


class LEDDriverEmulator(PtyDevice):
    """An Arduino-style LED driver answering ``ID?``, ``L <n>`` and ``L?``.

    Parameters
    ----------
    silent : never answer (to test the driver's timeout).
    """

    thread_name = "led-emulator"

    def __init__(self, silent: bool = False) -> None:
        super().__init__()
        self.level = 0
        self.silent = silent
        self.received: list[bytes] = []

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
