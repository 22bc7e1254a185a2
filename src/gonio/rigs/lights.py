"""Light sources (:class:`gonio.rigs.devices.Light`): on/off/intensity, simulated or an LED
driver speaking a line protocol. :mod:`gonio.rigs.factory` builds them from the rig file.

Backends (the rig file's ``[light] kind``):

* ``"sim"`` — :class:`SimulatedLight`: holds its state; the simulated camera reads it, so a
  dark frame taken with the light off really is dark.
* ``"serial"`` — :class:`SerialLEDLight`: an Arduino-style constant-current LED driver on a
  serial port (or any pyserial URL). Protocol, ASCII, one command per line, ``\\n``-terminated,
  every command answered by exactly one line:

  ==================  =====================  ==========================================
  command             reply                  meaning
  ==================  =====================  ==========================================
  ``ID?``             ``GONIO-LED <version>`` identify (checked when the port opens)
  ``L <n>``           ``OK``                 set the level to n per mille, 0..1000
  ``L?``              ``L <n>``              report the level
  anything wrong      ``ERR <reason>``       e.g. ``ERR range``, ``ERR syntax``
  ==================  =====================  ==========================================

  ``on()`` sends the stored intensity, ``off()`` sends ``L 0``. A reply other than the one
  expected, or none within the timeout, is a :class:`~gonio.errors.DeviceError`.
  :class:`gonio.rigs.sim.led.LEDDriverEmulator` implements the firmware side on a
  pseudo-terminal for tests.
"""

from __future__ import annotations

from gonio.errors import DeviceError, ParameterError

#: Levels are sent in per mille (0..1000), the resolution of a typical 10-bit PWM driver.
LEVEL_MAX = 1000


def _check_level(value: float) -> float:
    v = float(value)
    if not 0.0 <= v <= 1.0:
        raise ParameterError(f"light intensity must be in [0, 1], got {value}")
    return v


class SimulatedLight:
    """A light whose state the simulated camera reads (radiant intensity scales with it)."""

    def __init__(self, intensity: float = 1.0) -> None:
        self.intensity = _check_level(intensity)
        self.is_on = True

    def on(self) -> None:
        self.is_on = True

    def off(self) -> None:
        self.is_on = False

    def set_intensity(self, value: float) -> None:
        self.intensity = _check_level(value)

    @property
    def output(self) -> float:
        """Relative radiant output now (0 when off)."""
        return self.intensity if self.is_on else 0.0

    def close(self) -> None:
        pass


class SerialLEDLight:
    """An LED driver on a serial port speaking the line protocol of this module.

    Parameters
    ----------
    port : serial device path or pyserial URL (``serial_for_url``).
    baudrate : baud rate.
    timeout_s : reply timeout per command, seconds.
    intensity : initial relative intensity in [0, 1] (sent on :meth:`on`).
    """

    def __init__(
        self, port: str, baudrate: int = 115200, timeout_s: float = 1.0, intensity: float = 1.0
    ) -> None:
        import serial

        self.intensity = _check_level(intensity)
        self.is_on = False
        try:
            self._ser = serial.serial_for_url(port, baudrate=baudrate, timeout=timeout_s)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise DeviceError(f"light: cannot open {port}: {exc}") from None
        self.port = port
        try:
            ident = self._ask("ID?")
            if not ident.startswith("GONIO-LED"):
                raise DeviceError(f"light on {port}: unexpected identification {ident!r}")
            self._set(0)
        except BaseException:
            self._ser.close()
            raise

    def _ask(self, command: str) -> str:
        import serial

        try:
            self._ser.reset_input_buffer()
            self._ser.write(command.encode("ascii") + b"\n")
            self._ser.flush()
            line = self._ser.readline()
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"light on {self.port}: {exc}") from None
        if not line.endswith(b"\n"):
            raise DeviceError(f"light on {self.port}: no reply to {command!r}")
        reply = line.decode("ascii", "replace").strip()
        if reply.startswith("ERR"):
            raise DeviceError(f"light on {self.port}: {command!r} refused: {reply}")
        return reply

    def _set(self, level: int) -> None:
        reply = self._ask(f"L {level}")
        if reply != "OK":
            raise DeviceError(f"light on {self.port}: expected OK, got {reply!r}")

    def level(self) -> int:
        """The level the driver reports (per mille)."""
        reply = self._ask("L?")
        parts = reply.split()
        if len(parts) != 2 or parts[0] != "L" or not parts[1].isdigit():
            raise DeviceError(f"light on {self.port}: bad level reply {reply!r}")
        return int(parts[1])

    def on(self) -> None:
        self._set(round(self.intensity * LEVEL_MAX))
        self.is_on = True

    def off(self) -> None:
        self._set(0)
        self.is_on = False

    def set_intensity(self, value: float) -> None:
        self.intensity = _check_level(value)
        if self.is_on:
            self.on()

    def close(self) -> None:
        try:
            if self._ser.is_open:
                self.off()
        except DeviceError:
            pass
        finally:
            self._ser.close()
