"""Dynamixel Protocol 2.0 transactions over the real ``dynamixel_sdk``, with retries.

:class:`DynamixelBus` runs ping, read, write, sync write, sync read and reboot through
``dynamixel_sdk.PortHandler`` / ``PacketHandler(2.0)``, each retried with exponential backoff
after a timeout, a corrupt reply or a CRC error reported by the servo. A failing serial port
(adapter unplugged) is :class:`BusLost`, not retried. Every Goal Position packet first goes
through :attr:`DynamixelBus.goal_guard` (set by :class:`gonio.rigs.dynamixel.ServoChain`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import dynamixel_sdk as sdk
import serial

from gonio.errors import DeviceError
from gonio.rigs import control_table as ct
from gonio.rigs.config import BusConfig

try:  # pyserial's POSIX backend lets termios.error (not an OSError) through from tcflush
    from termios import error as _TermiosError
except ImportError:  # pragma: no cover - Windows

    class _TermiosError(Exception):
        pass


_PORT_ERRORS = (serial.SerialException, OSError, _TermiosError)


def _port_error_text(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    if isinstance(exc, _TermiosError) and len(exc.args) == 2:
        return str(exc.args[1])
    return str(exc) or type(exc).__name__


_RETRY_COMM = {sdk.COMM_RX_TIMEOUT, sdk.COMM_RX_CORRUPT, sdk.COMM_RX_FAIL, sdk.COMM_TX_FAIL}


class BusLost(DeviceError):
    """The serial port itself failed (adapter unplugged, port closed): no retry can help."""


class _PortHandler(sdk.PortHandler):
    """The SDK's PortHandler with an extra reply-timeout margin (``bus.timeout_margin_ms``).

    The SDK waits ``2 x 16 ms + 2 ms`` (USB latency timer) plus the transfer time for a reply;
    slow links (serial servers, a loaded host running the emulator) need more.
    """

    extra_timeout_ms: float = 0.0

    def setPacketTimeout(self, packet_length):
        super().setPacketTimeout(packet_length)
        self.packet_timeout += self.extra_timeout_ms

    def setPacketTimeoutMillis(self, msec):
        super().setPacketTimeoutMillis(msec + self.extra_timeout_ms)


class _URLPortHandler(_PortHandler):
    """PortHandler that opens pyserial URLs (``socket://``, ``rfc2217://``, ``loop://``)."""

    def setupPort(self, cflag_baud):
        if self.is_open:
            self.closePort()
        self.ser = serial.serial_for_url(
            self.port_name, baudrate=self.baudrate, bytesize=serial.EIGHTBITS, timeout=0
        )
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


@dataclass
class BusStats:
    """Counters of one bus session."""

    transactions: int = 0
    retries: int = 0
    timeouts: int = 0
    corrupt: int = 0
    crc_errors: int = 0
    resent_goals: int = 0


class DynamixelBus:
    """Protocol 2.0 transactions with retries.

    Parameters
    ----------
    port : str
        Serial device path or pyserial URL.
    baudrate : int
        Bits per second.
    retries : int
        Extra attempts after a timeout / corrupt reply / servo-reported CRC error.
    backoff_s : float
        Delay before the first retry; doubles each retry (capped at 0.2 s).
    timeout_margin_s : float
        Added to the SDK's reply timeout (about 34 ms plus transfer time).
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 1_000_000,
        retries: int = 5,
        backoff_s: float = 0.002,
        timeout_margin_s: float = 0.0,
    ):
        self.port_name = port
        self.baudrate = baudrate
        self.retries = retries
        self.backoff_s = backoff_s
        self.timeout_margin_s = timeout_margin_s
        self.stats = BusStats()
        self._port: sdk.PortHandler | None = None
        self._ph = sdk.PacketHandler(2.0)
        #: called with ``{servo id: ticks}`` before any Goal Position packet is written; raises
        #: to refuse it (:class:`gonio.rigs.guard.GoalGuard` on a :class:`ServoChain`)
        self.goal_guard: Callable[[Mapping[int, int]], object] | None = None
        #: ids whose last status packet carried the alert bit (hardware error pending)
        self.alerts: set[int] = set()

    @classmethod
    def from_config(cls, cfg: BusConfig, port: str | None = None) -> DynamixelBus:
        return cls(
            port or cfg.port,
            cfg.baudrate,
            cfg.retries,
            cfg.backoff_ms / 1000.0,
            cfg.timeout_margin_ms / 1000.0,
        )

    # --- port ---------------------------------------------------------------------------------
    def open(self) -> None:
        url = "://" in self.port_name
        port = (_URLPortHandler if url else _PortHandler)(self.port_name)
        port.extra_timeout_ms = self.timeout_margin_s * 1000.0
        try:
            ok = port.openPort() and port.setBaudRate(self.baudrate)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"cannot open servo bus {self.port_name}: {exc}") from None
        if not ok:
            raise DeviceError(f"cannot open servo bus {self.port_name} at {self.baudrate} baud")
        self._port = port

    def close(self) -> None:
        if self._port is not None and self._port.is_open:
            self._port.closePort()
        self._port = None

    def __enter__(self) -> DynamixelBus:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def port(self) -> sdk.PortHandler:
        if self._port is None:
            raise DeviceError("servo bus is not open")
        return self._port

    # --- retry core ---------------------------------------------------------------------------
    def _transact(self, what: str, fn: Callable[[], tuple], who: Callable[[], str] | None = None):
        """Run ``fn() -> (value, comm_result, error_byte)`` with retries; return value, error.

        ``who()`` names the servo at fault in the final error (for multi-servo transactions).
        """
        delay = self.backoff_s
        last = ""
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats.retries += 1
                time.sleep(delay)
                delay = min(delay * 2.0, 0.2)
            self.stats.transactions += 1
            try:
                value, comm, error = fn()
            except _PORT_ERRORS as exc:
                # the adapter was unplugged or the port went away: not a fault a retry fixes
                self._release()
                raise BusLost(
                    f"{what}: servo bus {self.port_name} lost ({_port_error_text(exc)})"
                ) from None
            except BaseException:
                # interrupted mid-transaction (a signal): leave the port usable for parking
                self._release()
                raise
            if comm in _RETRY_COMM:
                if comm == sdk.COMM_RX_TIMEOUT:
                    self.stats.timeouts += 1
                else:
                    self.stats.corrupt += 1
                last = self._ph.getTxRxResult(comm)
                continue
            if comm != sdk.COMM_SUCCESS:
                raise DeviceError(f"{what}: {self._ph.getTxRxResult(comm)}")
            num = error & 0x7F
            if num == sdk.ERRNUM_CRC:
                self.stats.crc_errors += 1
                last = "servo reported a CRC error"
                continue
            if num:
                raise DeviceError(f"{what}: {self._ph.getRxPacketError(num)}")
            return value, error
        culprit = who() if who is not None else ""
        raise DeviceError(
            f"{what}: {culprit + ' ' if culprit else ''}no valid reply after"
            f" {self.retries + 1} attempts ({last})"
        )

    def _release(self) -> None:
        if self._port is not None:
            self._port.is_using = False

    def _note_alert(self, servo_id: int, error: int) -> None:
        if error & sdk.ERRBIT_ALERT:
            self.alerts.add(servo_id)
        else:
            self.alerts.discard(servo_id)

    # --- transactions -------------------------------------------------------------------------
    def ping(self, servo_id: int) -> int:
        """Model Number of servo ``servo_id`` (raises DeviceError if it does not answer)."""
        model, error = self._transact(
            f"ping servo {servo_id}", lambda: self._ph.ping(self.port, servo_id)
        )
        self._note_alert(servo_id, error)
        return int(model)

    def read(self, servo_id: int, reg: tuple[int, int], signed: bool = False) -> int:
        """Read a 1, 2 or 4-byte register."""
        addr, n = reg

        def call():
            data, comm, err = self._ph.readTxRx(self.port, servo_id, addr, n)
            return data, comm, err

        data, error = self._transact(f"read servo {servo_id} @{addr}", call)
        self._note_alert(servo_id, error)
        return int.from_bytes(bytes(data[:n]), "little", signed=signed)

    def write(self, servo_id: int, reg: tuple[int, int], value: int) -> None:
        """Write a 1, 2 or 4-byte register and wait for the servo's acknowledgement."""
        addr, n = reg
        if reg == ct.GOAL_POSITION and self.goal_guard is not None:
            self.goal_guard({servo_id: value})
        data = list(int(value & ((1 << (8 * n)) - 1)).to_bytes(n, "little"))

        def call():
            comm, err = self._ph.writeTxRx(self.port, servo_id, addr, n, data)
            return None, comm, err

        _, error = self._transact(f"write servo {servo_id} @{addr}={value}", call)
        self._note_alert(servo_id, error)

    def sync_write(self, reg: tuple[int, int], values: Mapping[int, int]) -> None:
        """One Sync Write packet setting ``reg`` on every servo in ``values`` (no reply)."""
        addr, n = reg
        if reg == ct.GOAL_POSITION and self.goal_guard is not None:
            self.goal_guard(values)
        group = sdk.GroupSyncWrite(self.port, self._ph, addr, n)
        for sid, v in values.items():
            group.addParam(sid, list(int(v & ((1 << (8 * n)) - 1)).to_bytes(n, "little")))

        def call():
            return None, group.txPacket(), 0

        self._transact("sync write", call)

    def sync_read(self, addr: int, n: int, ids: list[int]) -> dict[int, bytes]:
        """One Sync Read of ``n`` bytes at ``addr`` from every servo in ``ids``.

        Uses the SDK's ``syncReadTx`` and per-servo ``readRx`` (rather than GroupSyncRead) so the
        error byte of every status packet is seen: its alert bit flags a hardware error.
        """

        failed: list[int] = []

        def call():
            failed.clear()
            comm = self._ph.syncReadTx(self.port, addr, n, list(ids), len(ids), False)
            if comm != sdk.COMM_SUCCESS:
                return None, comm, 0
            out: dict[int, bytes] = {}
            worst = 0
            for sid in ids:
                data, comm, err = self._ph.readRx(self.port, sid, n)
                if comm != sdk.COMM_SUCCESS:
                    self.port.is_using = False
                    failed.append(sid)
                    return None, comm, 0
                if len(data) != n:
                    failed.append(sid)
                    return None, sdk.COMM_RX_CORRUPT, 0
                self._note_alert(sid, err)
                if err & 0x7F:
                    worst = err
                out[sid] = bytes(data)
            return out, sdk.COMM_SUCCESS, worst

        value, _ = self._transact(
            f"sync read @{addr} from {ids}",
            call,
            lambda: f"servo {failed[0]} gave" if failed else "",
        )
        return value

    def reboot(self, servo_id: int) -> None:
        """Reboot a servo (clears a hardware error; RAM registers return to defaults)."""

        def call():
            comm, err = self._ph.reboot(self.port, servo_id)
            return None, comm, err

        self._transact(f"reboot servo {servo_id}", call)
        self.alerts.discard(servo_id)
