"""The simulated rig: a Dynamixel servo-chain emulator on a pseudo-terminal and a simulated sample.

The driver reaches the emulator through the real ``dynamixel_sdk`` on the pty's slave path, exactly
as it reaches a USB adapter on hardware.
"""

from gonio.rigs.sim.bus import FaultConfig, GoalRecord, ServoChainEmulator, ServoSpec

__all__ = ["FaultConfig", "GoalRecord", "ServoChainEmulator", "ServoSpec"]
