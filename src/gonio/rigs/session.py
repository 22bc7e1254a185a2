"""Open a rig from its file: start the emulator for ``bus.port = "sim"``, connect the driver.

This is the only place where the simulated and the hardware rig differ: for the simulated rig
the servo-chain emulator is started on a pseudo-terminal and its slave path replaces the port;
everything after that (``dynamixel_sdk``, :class:`~gonio.rigs.dynamixel.ServoChain`) is the
same code as on hardware.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from gonio.rigs.config import RigConfig
from gonio.rigs.dynamixel import ServoChain
from gonio.rigs.sim.bus import FaultConfig, ServoChainEmulator, ServoSpec


@dataclass
class RigSession:
    """An open rig: the driver, and the emulator when the rig is simulated."""

    rig: RigConfig
    chain: ServoChain
    emulator: ServoChainEmulator | None = None

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
):
    """Context manager yielding a connected :class:`RigSession`.

    ``faults``, ``goal_log_path``, ``time_scale`` and ``log_dir`` apply to the simulated rig
    only: with ``log_dir`` (a run directory) the emulator appends every Goal Position it
    receives to ``log_dir/sim_goals.jsonl`` and, when the rig file sets ``[sim]
    packet_log = true``, every instruction packet to ``log_dir/sim_packets.jsonl``.
    """
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
    try:
        chain = ServoChain(rig, port=port)
        chain.open()
        try:
            if initialize:
                chain.initialize()
            yield RigSession(rig, chain, emu)
        finally:
            chain.close()
    finally:
        if emu is not None:
            emu.stop()
