"""Open a rig from its file: every device it names, in a defined order, closed in reverse.

:func:`open_rig` opens the devices of :data:`DEVICES` in that order: the light, the camera
(which the simulated camera's rendering reads the light from; a bad camera is found before the
bus is opened), then the servos. Every way out of the block closes what was opened in reverse
order: servos (the driver, then the emulator), camera, light. Parking is the caller's (the run
engine parks inside the block, :mod:`gonio.acquire.stopping`). The backends come from
:mod:`gonio.rigs.factory`; the protocols are in :mod:`gonio.rigs.devices`.

For the simulated rig (``bus.port = "sim"``) the servo-chain emulator is started on a
pseudo-terminal and its slave path replaces the port; everything after that
(``dynamixel_sdk``, :class:`~gonio.rigs.dynamixel.ServoChain`) is the same code as on hardware.
The port is locked before the driver opens it (:func:`gonio.locks.hold_port`, keyed by its real
path): a second process on the same adapter or pseudo-terminal is refused in one line naming
the holder's PID, before it sends any packet. The simulator's file logs never stop its bus: one
that cannot be written (a full disk) stops, and the error leaving the session says so.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Collection
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from gonio.errors import ParameterError
from gonio.locks import hold_port
from gonio.rigs import factory
from gonio.rigs.config import RigConfig
from gonio.rigs.dynamixel import ServoChain
from gonio.rigs.sim.bus import FaultConfig, ServoChainEmulator, ServoSpec

if TYPE_CHECKING:
    from gonio.rigs.devices import Camera, Light
    from gonio.rigs.sim.camera import HolderLayout

#: The devices of a rig, in the order :func:`open_rig` opens them (it closes them in reverse).
DEVICES = ("light", "camera", "servos")


@dataclass
class RigSession:
    """An open rig: its devices (None where not opened), and the emulator when the rig is
    simulated.

    Attributes
    ----------
    rig : the rig file.
    chain : the servos (:class:`gonio.rigs.devices.Servos`).
    emulator : the servo-chain emulator of a simulated rig.
    camera : the camera (:class:`gonio.rigs.devices.Camera`).
    light : the light (:class:`gonio.rigs.devices.Light`), on.
    holder : the sample holder the camera sees (board, sample, white reference).
    """

    rig: RigConfig
    chain: ServoChain | None
    emulator: ServoChainEmulator | None = None
    camera: Camera | None = None
    light: Light | None = None
    holder: HolderLayout | None = None

    @property
    def time_scale(self) -> float:
        """Rig seconds per wall second: the emulator's time scale, 1 for hardware."""
        return self.emulator.time_scale if self.emulator is not None else 1.0


def make_emulator(
    rig: RigConfig,
    faults: FaultConfig | None = None,
    goal_log_path: str | os.PathLike | None = None,
    time_scale: float | None = None,
    packet_log_path: str | os.PathLike | None = None,
) -> ServoChainEmulator:
    """An emulator with the rig's servos, each starting at its park angle."""
    specs = []
    for j in rig.joints:
        start = j.to_ticks(rig.park_deg.get(j.name, j.zero_offset_deg))
        specs.append(ServoSpec(j.id, j.model, rig.sim.firmware, start))
    if faults is None:
        faults = FaultConfig(**rig.sim.faults)
    return ServoChainEmulator(
        specs,
        faults=faults,
        time_scale=time_scale or rig.sim.time_scale,
        settle_ticks=rig.sim.settle_ticks,
        seed=rig.sim.seed,
        goal_log_path=goal_log_path,
        packet_log_path=packet_log_path,
    )


@contextmanager
def open_rig(
    rig: RigConfig,
    faults: FaultConfig | None = None,
    goal_log_path: str | os.PathLike | None = None,
    initialize: bool = True,
    time_scale: float | None = None,
    log_dir: str | os.PathLike | None = None,
    devices: Collection[str] = DEVICES,
    before_servos: Callable[[], None] | None = None,
):
    """Context manager yielding a :class:`RigSession` with the rig's devices open.

    ``devices`` picks which of :data:`DEVICES` to open (always in that order): ``gonio rig
    check`` opens the servos only; a camera needs its light. The light is switched on once the
    camera is open. ``before_servos()`` is called between the camera and the servos: the run
    engine raises there a stop asked for while the camera opened, so that no servo is powered.

    ``faults``, ``goal_log_path``, ``time_scale`` and ``log_dir`` apply to the simulated rig
    only: with ``log_dir`` (a run directory) the emulator appends every Goal Position it
    receives to ``log_dir/sim_goals.jsonl`` and, when the rig file sets ``[sim]
    packet_log = true``, every instruction packet to ``log_dir/sim_packets.jsonl``.
    """
    unknown = sorted(set(devices) - set(DEVICES))
    if unknown:
        raise ParameterError(f"no such device {unknown[0]!r}: the devices are {DEVICES}")
    if "camera" in devices and "light" not in devices:
        raise ParameterError("the camera is opened with its light")
    with ExitStack() as stack:
        ses = RigSession(rig, None)
        if "light" in devices:
            ses.light = factory.open_light(rig)
            stack.callback(ses.light.close)
        if "camera" in devices:
            ses.holder = factory.holder(rig)
            ses.camera = factory.open_camera(rig, ses.light, ses.holder)
            stack.callback(ses.camera.close)
        if ses.light is not None:
            ses.light.on()
        if "servos" in devices:
            if before_servos is not None:
                before_servos()
            ses.emulator, ses.chain = _open_servos(
                stack, rig, faults, goal_log_path, initialize, time_scale, log_dir
            )
        try:
            yield ses
        except BaseException as exc:
            if ses.emulator is not None and ses.emulator.file_log_error is not None:
                e = ses.emulator.file_log_error
                exc.add_note(f"the simulator's log stopped at {e.filename}: {e.strerror or e}")
            raise


def _open_servos(stack, rig, faults, goal_log_path, initialize, time_scale, log_dir):
    """Start the emulator (simulated rig) and open the driver; both closed by ``stack``."""
    emu = None
    port = None
    if rig.is_sim:
        packets = None
        if log_dir is not None:
            goal_log_path = goal_log_path or Path(log_dir) / "sim_goals.jsonl"
            if rig.sim.packet_log:
                packets = Path(log_dir) / "sim_packets.jsonl"
        emu = make_emulator(rig, faults, goal_log_path, time_scale, packets)
        port = emu.start()
        stack.callback(emu.stop)
    # one process drives a port: a second one is refused here, before it sends any packet
    stack.enter_context(hold_port(port or rig.bus.port))
    chain = ServoChain(rig, port=port)
    chain.open()
    stack.callback(chain.close)
    if initialize:
        chain.initialize()
    return emu, chain
