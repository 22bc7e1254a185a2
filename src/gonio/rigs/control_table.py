"""X-series control table (Protocol 2.0 firmware) and unit conversions.

Addresses, sizes and units follow the ROBOTIS e-Manual for the X series (XM430-W350,
XL430-W250, ...). Only the registers the driver and the emulator use are named here.
"""

from __future__ import annotations

import math

# EEPROM area (writable only while torque is off).
MODEL_NUMBER = (0, 2)
MODEL_INFORMATION = (2, 4)
FIRMWARE_VERSION = (6, 1)
ID = (7, 1)
BAUD_RATE = (8, 1)
RETURN_DELAY_TIME = (9, 1)
DRIVE_MODE = (10, 1)
OPERATING_MODE = (11, 1)
HOMING_OFFSET = (20, 4)
MOVING_THRESHOLD = (24, 4)
TEMPERATURE_LIMIT = (31, 1)
VELOCITY_LIMIT = (44, 4)
MAX_POSITION_LIMIT = (48, 4)
MIN_POSITION_LIMIT = (52, 4)
SHUTDOWN = (63, 1)
EEPROM_END = 64

# RAM area.
TORQUE_ENABLE = (64, 1)
LED = (65, 1)
STATUS_RETURN_LEVEL = (68, 1)
REGISTERED_INSTRUCTION = (69, 1)
HARDWARE_ERROR_STATUS = (70, 1)
GOAL_VELOCITY = (104, 4)
PROFILE_ACCELERATION = (108, 4)
PROFILE_VELOCITY = (112, 4)
GOAL_POSITION = (116, 4)
REALTIME_TICK = (120, 2)
MOVING = (122, 1)
MOVING_STATUS = (123, 1)
PRESENT_CURRENT = (126, 2)
PRESENT_VELOCITY = (128, 4)
PRESENT_POSITION = (132, 4)
PRESENT_INPUT_VOLTAGE = (144, 2)
PRESENT_TEMPERATURE = (146, 1)
TABLE_SIZE = 147

#: Block read each poll by the driver: Goal Position .. Present Position (20 bytes).
POLL_BLOCK = (GOAL_POSITION[0], PRESENT_POSITION[0] + 4 - GOAL_POSITION[0])

# Operating modes.
MODE_POSITION = 3
MODE_EXTENDED_POSITION = 4
OPERATING_MODES = {"position": MODE_POSITION, "extended_position": MODE_EXTENDED_POSITION}

# Hardware Error Status bits.
HW_INPUT_VOLTAGE = 0x01
HW_OVERHEATING = 0x04
HW_MOTOR_ENCODER = 0x08
HW_ELECTRICAL_SHOCK = 0x10
HW_OVERLOAD = 0x20
HW_ERROR_NAMES = {
    HW_INPUT_VOLTAGE: "input voltage",
    HW_OVERHEATING: "overheating",
    HW_MOTOR_ENCODER: "motor encoder",
    HW_ELECTRICAL_SHOCK: "electrical shock",
    HW_OVERLOAD: "overload",
}

#: Model numbers (Model Number register) of common X-series servos.
MODELS = {
    "XL330-M077": 1190,
    "XL330-M288": 1200,
    "XL430-W250": 1060,
    "XC430-W150": 1070,
    "XC430-W240": 1080,
    "XM430-W210": 1030,
    "XM430-W350": 1020,
    "XH430-W210": 1010,
    "XH430-W350": 1000,
    "XM540-W150": 1130,
    "XM540-W270": 1120,
    "XH540-W150": 1110,
    "XH540-W270": 1100,
}
MODEL_NAMES = {v: k for k, v in MODELS.items()}

TICKS_PER_REV = 4096
#: Position mode range (one turn); extended position mode is +-256 turns.
POSITION_RANGE = {MODE_POSITION: (0, 4095), MODE_EXTENDED_POSITION: (-1_048_575, 1_048_575)}
CENTER_TICK = 2048
#: Profile Velocity unit: 0.229 rev/min.
VELOCITY_UNIT_RPM = 0.229
#: Profile Acceleration unit: 214.577 rev/min^2.
ACCELERATION_UNIT_RPM2 = 214.577
#: Largest Profile Velocity / Profile Acceleration value (e-Manual range 0..32767; 0 = no limit).
PROFILE_RAW_MAX = 32767


def hardware_error_text(bits: int) -> str:
    """Human-readable list of the Hardware Error Status bits set in ``bits``."""
    names = [name for bit, name in HW_ERROR_NAMES.items() if bits & bit]
    return ", ".join(names) if names else "none"


def velocity_raw_to_deg_s(raw: int) -> float:
    """Profile Velocity register value -> servo-shaft speed in degrees per second."""
    return raw * VELOCITY_UNIT_RPM * 360.0 / 60.0


def deg_s_to_velocity_raw(deg_s: float) -> int:
    """Servo-shaft speed in degrees per second -> Profile Velocity register value (>= 1)."""
    return max(1, round(deg_s * 60.0 / (360.0 * VELOCITY_UNIT_RPM)))


def acceleration_raw_to_deg_s2(raw: int) -> float:
    """Profile Acceleration register value -> degrees per second squared."""
    return raw * ACCELERATION_UNIT_RPM2 * 360.0 / 3600.0


def deg_s2_to_acceleration_raw(deg_s2: float) -> int:
    """Degrees per second squared -> Profile Acceleration register value (>= 1)."""
    return max(1, round(deg_s2 * 3600.0 / (360.0 * ACCELERATION_UNIT_RPM2)))


def trapezoid_time(distance: float, v_max: float, a_max: float) -> float:
    """Duration of a rest-to-rest trapezoidal (or triangular) move.

    Parameters
    ----------
    distance : float
        Travel, any unit (absolute value is used).
    v_max, a_max : float
        Speed and acceleration limits in the same unit per second (per second squared).
        ``a_max <= 0`` means an instantaneous speed change (rectangular profile).
    """
    d = abs(distance)
    if d == 0.0:
        return 0.0
    if a_max <= 0:
        return d / v_max
    d_ramp = v_max * v_max / a_max  # distance of accelerating plus decelerating at full speed
    if d >= d_ramp:
        return d / v_max + v_max / a_max
    return 2.0 * math.sqrt(d / a_max)


def trapezoid_position(distance: float, v_max: float, a_max: float, t: float) -> float:
    """Signed travel after ``t`` seconds of the move of :func:`trapezoid_time` (same units)."""
    sign = 1.0 if distance >= 0 else -1.0
    d = abs(distance)
    total = trapezoid_time(d, v_max, a_max)
    if t >= total:
        return distance
    if t <= 0:
        return 0.0
    if a_max <= 0:
        return sign * v_max * t
    t_acc = min(v_max / a_max, total / 2.0)
    v_peak = a_max * t_acc
    if t < t_acc:
        s = 0.5 * a_max * t * t
    elif t < total - t_acc:
        s = 0.5 * a_max * t_acc * t_acc + v_peak * (t - t_acc)
    else:
        tr = total - t
        s = d - 0.5 * a_max * tr * tr
    return sign * s
