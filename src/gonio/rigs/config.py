"""Rig files: TOML descriptions of a gonioreflectometer, validated against a JSON schema.

The schema (``data-schema/rig.schema.json``) is generated from :data:`SPEC` below, the single
definition of every key, its type, unit and range; ``python -m gonio.rigs.config --schema``
prints it. :func:`load_rig` parses a rig file with :mod:`tomllib`, validates it with
:mod:`jsonschema` and returns a :class:`RigConfig`; every error is one line naming the key and
the line of the file it is on.

Rig names: ``load_rig("sim")`` finds the rig shipped as package data (``gonio/rigs/sim.toml``);
anything containing a path separator or ending in ``.toml`` is a path.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import jsonschema

from gonio._bounded import bad_number_path, loads_toml
from gonio.errors import PlanError, RigConfigError
from gonio.rigs import control_table as ct
from gonio.rigs.toml_lines import key_line, non_finite, where

__all__ = ["RigConfig", "key_line", "load_rig", "non_finite", "parse_rig", "rig_schema", "where"]

# --- the definition -------------------------------------------------------------------------
# Each leaf: (json type, description, extra schema keywords). Tables are dicts; arrays of tables
# are one-element lists. ``required`` lists are attached under the "__required__" key.


def _num(desc: str, **kw: Any) -> dict:
    return {"type": "number", "description": desc, **kw}


def _int(desc: str, **kw: Any) -> dict:
    return {"type": "integer", "description": desc, **kw}


def _str(desc: str, **kw: Any) -> dict:
    return {"type": "string", "description": desc, **kw}


def _bool(desc: str) -> dict:
    return {"type": "boolean", "description": desc}


_JOINT = {
    "__doc__": "One servo-driven joint.",
    "__required__": ["name", "id", "model", "min_deg", "max_deg"],
    "name": _str(
        "Joint name, referenced by [layout], [park] and [safety].",
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
    ),
    "id": _int("Servo id on the bus.", minimum=0, maximum=252),
    "model": _str(
        "Servo model (checked against the Model Number the servo reports).", enum=sorted(ct.MODELS)
    ),
    "operating_mode": _str("Servo operating mode.", enum=sorted(ct.OPERATING_MODES)),
    "gear_ratio": _num("Servo turns per joint turn (> 0).", exclusiveMinimum=0),
    "zero_offset_deg": _num("Joint angle (deg) when the servo reads its centre tick 2048."),
    "direction": _int("+1 or -1: sign of joint angle per servo angle.", enum=[-1, 1]),
    "min_deg": _num("Lower software limit of the joint (deg)."),
    "max_deg": _num("Upper software limit of the joint (deg)."),
    "profile_velocity_deg_s": _num(
        "Joint speed of the trapezoidal profile (deg/s).", exclusiveMinimum=0
    ),
    "profile_acceleration_deg_s2": _num(
        "Joint acceleration of the profile (deg/s^2).", exclusiveMinimum=0
    ),
    "settle_tolerance_deg": _num(
        "Settled when |present - goal| <= this (deg).", exclusiveMinimum=0
    ),
}

SPEC: dict = {
    "__doc__": "A gonioreflectometer: servo bus, joints, kinematic layout, devices, safety.",
    "__required__": ["name", "bus", "joints", "layout", "park", "safety"],
    "name": _str("Rig name."),
    "description": _str("Free text."),
    "bus": {
        "__doc__": "The Dynamixel bus.",
        "__required__": ["port"],
        "port": _str(
            "Serial device (/dev/ttyUSB0, COM3), a pyserial URL (socket://host:port, rfc2217://...),"
            " or 'sim' for the built-in emulator on a pseudo-terminal."
        ),
        "baudrate": _int(
            "Baud rate.",
            enum=[9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000, 4500000],
        ),
        "protocol": _num("Dynamixel protocol version; only 2.0 is supported.", enum=[2.0]),
        "retries": _int(
            "Retries of a transaction after a timeout or CRC error.", minimum=0, maximum=50
        ),
        "backoff_ms": _num(
            "First retry delay (ms); doubles at every retry.", minimum=0, maximum=10_000
        ),
        "timeout_margin_ms": _num(
            "Added to dynamixel-sdk's reply timeout (2 x 16 ms USB latency + 2 ms + transfer),"
            " for slow links or a loaded host (ms).",
            minimum=0,
            maximum=60_000,
        ),
        "motion_timeout_s": _num(
            "Margin (s) added to the predicted move time before a move is declared stuck.",
            exclusiveMinimum=0,
            maximum=3600,
        ),
        "poll_interval_ms": _num(
            "Delay between position polls while settling (ms).", minimum=0, maximum=10_000
        ),
        "max_recoveries": _int(
            "Unused: a hardware error stops the run, nothing reboots (accepted in old files).",
            minimum=0,
            maximum=10,
        ),
    },
    "joints": [_JOINT],
    "layout": {
        "__doc__": "Kinematic layout (see gonio.rigs.kinematics for the frames).",
        "__required__": ["light", "camera", "tilt", "rotation"],
        "light": _str("Joint carrying the light arm (rotates in the measurement plane)."),
        "camera": _str("Joint carrying the camera arm (same axis as the light arm)."),
        "tilt": _str("Joint tilting the sample out of the measurement plane."),
        "rotation": _str("Joint rotating the sample about its normal (turntable)."),
        "light_distance_m": _num("Light to sample centre (m).", exclusiveMinimum=0),
        "camera_distance_m": _num("Camera to sample centre (m).", exclusiveMinimum=0),
    },
    "camera": {
        "__doc__": "The camera.",
        "kind": _str(
            "Camera backend: 'sim' (virtual camera writing DNG files: the imaging pipeline),"
            " 'sim-sample' (a direct BRDF reading of the simulated sample without images: fast"
            " motion and bookkeeping tests), 'gphoto2' (a tethered camera via a command-line"
            " program), 'folder' (raw files dropped into a folder by the camera's own software).",
            enum=["sim", "sim-sample", "gphoto2", "folder"],
        ),
        "exposure_s": _num("Default (first probe) exposure (s).", exclusiveMinimum=0),
        "capture_time_s": _num(
            "Simulated capture duration (s, wall clock).", minimum=0, maximum=3600
        ),
        # --- imaging (RAW backends) ---
        "width": _int("Image width (pixels).", minimum=16, maximum=20000),
        "height": _int("Image height (pixels).", minimum=16, maximum=20000),
        "focal_px": _num("Focal length (pixels; pinhole, no distortion).", exclusiveMinimum=0),
        "supersample": _int("Simulated camera: rays per pixel along each axis.", minimum=1),
        "t_min_s": _num("Shortest exposure the camera takes (s).", exclusiveMinimum=0),
        "t_max_s": _num("Longest exposure the camera takes (s).", exclusiveMinimum=0),
        "snr_target": _num("SNR every sample/reference pixel reaches in some bracket.", minimum=1),
        "headroom": _num(
            "Fraction of the full well the brightest pixel may fill.", exclusiveMinimum=0, maximum=1
        ),
        "planning": _bool("Plan exposures from the previous frame (false: fixed brackets)."),
        "fixed_brackets": {
            "type": "array",
            "minItems": 1,
            "items": {"type": "number", "exclusiveMinimum": 0},
            "description": "Exposures relative to exposure_s when planning is off.",
        },
        "spot_radius_m": _num("Radius of the measured spot on the sample (m).", exclusiveMinimum=0),
        "bloom_guard_px": _int(
            "HDR merge: a frame is not used for pixels this close (pixels) to one it saturates"
            " (blooming and crosstalk); 0 uses every unsaturated pixel.",
            minimum=0,
            maximum=8,
        ),
        "sensor": {
            "__doc__": "Sensor noise model (EMVA 1288), also used for merge weights.",
            "gain": _num("Conversion gain (DN per electron).", exclusiveMinimum=0),
            "read_noise": _num("Read noise (electrons RMS).", minimum=0),
            "dark_current": _num("Dark current (electrons/s).", minimum=0),
            "full_well": _num("Full-well capacity (electrons).", exclusiveMinimum=0),
            "black_level": _int("Black level (DN).", minimum=0),
            "bits": _int("ADC bits.", minimum=8, maximum=16),
            "cfa": _str("Bayer tile, row-major.", enum=["RGGB", "BGGR", "GRBG", "GBRG"]),
            "shutter_error": _num("Simulated: relative exposure-time error (1 sigma).", minimum=0),
        },
        "program": _str("gphoto2: the program to run (name on PATH or path)."),
        "port": _str("gphoto2: --port of the camera (e.g. usb:001,004)."),
        "shutter_key": _str("gphoto2: config key of the shutter speed."),
        "timeout_s": _num(
            "gphoto2/folder: longest wait for a frame (s).", exclusiveMinimum=0, maximum=86_400
        ),
        "folder": _str("folder: directory the camera software writes raw files into."),
        "pattern": _str("folder: glob of the raw files (e.g. *.dng, *.CR2)."),
    },
    "light": {
        "__doc__": "The light source.",
        "kind": _str(
            "Light backend: 'sim', or 'serial' (LED driver speaking gonio's line protocol,"
            " see gonio.rigs.lights).",
            enum=["sim", "serial"],
        ),
        "irradiance_w_m2": _num(
            "Irradiance on a surface facing the light (W/m^2).", exclusiveMinimum=0
        ),
        "intensity": _num("Relative output when on, 0..1.", minimum=0, maximum=1),
        "port": _str("serial: device path or pyserial URL."),
        "baudrate": _int("serial: baud rate.", minimum=300),
        "timeout_s": _num("serial: reply timeout (s).", exclusiveMinimum=0, maximum=3600),
    },
    "park": {
        "__doc__": "Park pose: joint name -> angle (deg). Joints not named keep their angle.",
        "__additional__": _num("Park angle of that joint (deg)."),
    },
    "safety": {
        "__doc__": "Safety margins.",
        "__required__": ["min_light_camera_deg"],
        "min_light_camera_deg": _num(
            "Minimum angle between the light and camera arms, so neither shadows the other or"
            " hits it (deg).",
            minimum=0,
            maximum=180,
        ),
        "arms_can_pass": _bool(
            "Whether the light and camera arms can pass each other (different heights/radii);"
            " if not (default), they keep the order they have in the park pose."
        ),
        "max_theta_deg": _num(
            "Largest incident or outgoing polar angle allowed (deg).",
            exclusiveMinimum=0,
            maximum=90,
        ),
        "keepout": [
            {
                "__doc__": (
                    "A sector a joint must never enter or cross (e.g. an arm would hit the"
                    " column): the joint stays on the park angle's side of it."
                ),
                "__required__": ["joint", "min_deg", "max_deg"],
                "joint": _str("Joint name."),
                "min_deg": _num("Sector start (deg)."),
                "max_deg": _num("Sector end (deg)."),
                "reason": _str("Why (shown when a pose is refused)."),
            }
        ],
    },
    "sim": {
        "__doc__": "The simulated rig (used when bus.port = 'sim').",
        "time_scale": _num(
            "Simulated seconds per wall-clock second.", exclusiveMinimum=0, maximum=1e6
        ),
        "settle_ticks": _int(
            "Max settling error of a servo (encoder ticks, 0.088 deg).", minimum=0, maximum=50
        ),
        "seed": _int(
            "Seed of settling errors and measurement noise.", minimum=0, maximum=2**63 - 1
        ),
        "firmware": _int("Firmware version the emulated servos report.", minimum=0, maximum=255),
        "noise_rel": _num("Relative measurement noise (1 sigma).", minimum=0),
        "noise_abs": _num("Absolute measurement noise floor (1/sr, 1 sigma).", minimum=0),
        "packet_log": _bool(
            "Append every instruction packet the emulator receives to RUN/sim_packets.jsonl"
            " (tests and debugging; about 100 bytes per packet)."
        ),
        "sample": {
            "__doc__": (
                "Ground-truth BRDF of the simulated sample: a model (Node.to_dict() form: type,"
                " params) or file = path of a tabulated BRDF (relative to the rig file), or"
                " ARCHIVE.zip::NAME, a member of a neural-BRDF archive."
            ),
            "__additional__": {},
        },
        "faults": {
            "__doc__": "Injected bus faults (probabilities per packet / per move).",
            "drop": _num("Lost instruction packets.", minimum=0, maximum=1),
            "garble": _num("Corrupted status packets.", minimum=0, maximum=1),
            "crc": _num("Instructions arriving with a CRC error.", minimum=0, maximum=1),
            "overload": _num(
                "Moves ending in an overload (torque shutdown).", minimum=0, maximum=1
            ),
            "seed": _int("Fault seed.", minimum=0, maximum=2**63 - 1),
            "block_servo": _int("Servo id of a joint that meets an obstacle (0: none).", minimum=0),
            "block_after": _int("Its moves before the one stopped half-way.", minimum=0),
        },
    },
}


def _to_schema(node: Any) -> dict:
    if isinstance(node, list):
        return {"type": "array", "minItems": 1, "items": _to_schema(node[0])}
    if isinstance(node, dict) and ("type" in node or node == {}):
        return dict(node)
    out: dict = {"type": "object", "description": node.get("__doc__", "")}
    props = {k: _to_schema(v) for k, v in node.items() if not k.startswith("__")}
    if props:
        out["properties"] = props
    if "__required__" in node:
        out["required"] = list(node["__required__"])
    if "__additional__" in node:
        out["additionalProperties"] = _to_schema(node["__additional__"])
    else:
        out["additionalProperties"] = False
    return out


def rig_schema() -> dict:
    """The JSON schema (draft 2020-12) of rig files, generated from :data:`SPEC`."""
    schema = _to_schema(SPEC)
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://gonio.invalid/schema/rig.schema.json",
        "title": "gonio rig file",
        **schema,
    }


# --- typed configuration ------------------------------------------------------------------


@dataclass(frozen=True)
class BusConfig:
    port: str
    baudrate: int = 1_000_000
    protocol: float = 2.0
    retries: int = 5
    backoff_ms: float = 2.0
    timeout_margin_ms: float = 0.0
    motion_timeout_s: float = 5.0
    poll_interval_ms: float = 2.0
    max_recoveries: int = 2


@dataclass(frozen=True)
class JointConfig:
    """A joint. Angles in degrees as typed in the rig file (converted to radians at use)."""

    name: str
    id: int
    model: str
    min_deg: float
    max_deg: float
    operating_mode: str = "position"
    gear_ratio: float = 1.0
    zero_offset_deg: float = 0.0
    direction: int = 1
    profile_velocity_deg_s: float = 60.0
    profile_acceleration_deg_s2: float = 120.0
    settle_tolerance_deg: float = 0.5

    def to_ticks(self, angle_deg: float) -> int:
        """Joint angle (deg) -> Goal Position ticks; PlanError if it has none (NaN, inf)."""
        t = servo_ticks(self, angle_deg)
        if not math.isfinite(t):
            raise PlanError(f"joint {self.name}: {angle_deg} deg has no servo tick")
        return round(t)

    def from_ticks(self, ticks: int) -> float:
        """Present Position ticks -> joint angle (deg)."""
        servo_deg = (ticks - ct.CENTER_TICK) * 360.0 / ct.TICKS_PER_REV
        return self.zero_offset_deg + servo_deg / (self.gear_ratio * self.direction)

    @property
    def tolerance_ticks(self) -> int:
        # a validated rig has 0 < settle_tolerance_deg <= its range, so this is finite
        return max(
            1, math.floor(self.settle_tolerance_deg * self.gear_ratio * ct.TICKS_PER_REV / 360.0)
        )

    def move_time(self, delta_deg):
        """Rest-to-rest time (s) of a move of ``delta_deg`` under this joint's profile."""
        import numpy as np

        d = np.abs(np.asarray(delta_deg, dtype=float))
        v, a = self.profile_velocity_deg_s, self.profile_acceleration_deg_s2
        d_ramp = v * v / a
        return np.where(d >= d_ramp, d / v + v / a, 2.0 * np.sqrt(d / a))


@dataclass(frozen=True)
class Keepout:
    joint: str
    min_deg: float
    max_deg: float
    reason: str = "keep-out sector"


@dataclass(frozen=True)
class LayoutConfig:
    light: str
    camera: str
    tilt: str
    rotation: str
    light_distance_m: float = 0.5
    camera_distance_m: float = 0.5


@dataclass(frozen=True)
class SafetyConfig:
    min_light_camera_deg: float
    max_theta_deg: float = 85.0
    arms_can_pass: bool = False
    keepout: tuple[Keepout, ...] = ()


@dataclass(frozen=True)
class SimConfig:
    time_scale: float = 50.0
    settle_ticks: int = 2
    seed: int = 0
    firmware: int = 52
    noise_rel: float = 0.01
    noise_abs: float = 1e-4
    packet_log: bool = False
    sample: dict = field(default_factory=lambda: {"type": "Lambert", "params": {"albedo": [0.5]}})
    faults: dict = field(default_factory=dict)


@dataclass(frozen=True)
class RigConfig:
    """A validated rig file."""

    name: str
    bus: BusConfig
    joints: tuple[JointConfig, ...]
    layout: LayoutConfig
    park_deg: dict[str, float]
    safety: SafetyConfig
    camera: dict = field(default_factory=dict)
    light: dict = field(default_factory=dict)
    sim: SimConfig = field(default_factory=SimConfig)
    description: str = ""
    source: str = ""
    text: str = ""

    def joint(self, name: str) -> JointConfig:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    @property
    def is_sim(self) -> bool:
        return self.bus.port == "sim"


# --- loading ------------------------------------------------------------------------------


def _schema_error_message(err: jsonschema.ValidationError, source: str, text: str) -> str:
    path = tuple(err.absolute_path)
    if err.validator == "required":
        missing = re.findall(r"'([^']+)' is a required property", err.message)
        key = missing[0] if missing else "?"
        full = (*path, key)
        dotted = ".".join(f"[{k}]" if isinstance(k, int) else str(k) for k in full).replace(
            ".[", "["
        )
        line = key_line(text, path) if path else None
        loc = f"{source}:{line}" if line else source
        return f"{loc}: missing required key {dotted}"
    if err.validator == "additionalProperties":
        extra = re.findall(r"'([^']+)' was unexpected", err.message)
        key = extra[0] if extra else "?"
        return f"{where(source, text, (*path, key))}: unknown key"
    return f"{where(source, text, path)}: {err.message}"


def _find(name_or_path: str | Path) -> tuple[str, str]:
    s = str(name_or_path)
    if "/" in s or "\\" in s or s.endswith(".toml"):
        p = Path(s)
        try:
            return p.read_text(encoding="utf-8"), str(p)
        except FileNotFoundError:
            raise RigConfigError(f"rig file {s} not found") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise RigConfigError(f"cannot read rig file {s}: {exc}") from None
    res = resources.files("gonio.rigs").joinpath(f"{s}.toml")
    if not res.is_file():
        names = ", ".join(shipped_rigs())
        raise RigConfigError(f"unknown rig {s!r} (shipped rigs: {names}; or give a path)")
    return res.read_text(encoding="utf-8"), f"{s}.toml"


def shipped_rigs() -> list[str]:
    """Names of the rigs shipped as package data."""
    return sorted(
        r.name[:-5] for r in resources.files("gonio.rigs").iterdir() if r.name.endswith(".toml")
    )


def load_rig(name_or_path: str | Path, check_sample_model: bool = True) -> RigConfig:
    """Load and validate a rig file (a shipped rig name or a path); raise RigConfigError.

    ``check_sample_model=False`` leaves out one check: that a ``[sim.sample]`` model
    description builds a gonio model, which imports the model code (JAX, about a second). A
    sample ``file`` is still checked to exist. ``gonio plan`` uses it; ``gonio acquire`` checks
    the model before any motion.
    """
    text, source = _find(name_or_path)
    return parse_rig(text, source, check_sample_model)


def parse_rig(text: str, source: str = "<rig>", check_sample_model: bool = True) -> RigConfig:
    """Parse and validate rig-file ``text``; ``source`` names it in error messages
    (``check_sample_model``: see :func:`load_rig`)."""
    data = loads_toml(text, source, RigConfigError)  # size and nesting bounds
    # jsonschema's minimum/maximum accept NaN (every comparison with it is false), and TOML
    # spells nan and inf: refuse every non-finite number before anything else looks at it
    for path, value in non_finite(data):
        raise RigConfigError(f"{where(source, text, path)}: {value} is not a finite number")
    validator = jsonschema.Draft202012Validator(rig_schema())
    errors = sorted(validator.iter_errors(data), key=lambda e: (len(e.absolute_path), str(e.path)))
    if errors:
        raise RigConfigError(_schema_error_message(errors[0], source, text))
    # its consistency checks name the file line and quantity
    rig = _build(data, text, source, check_sample_model)
    # no rig quantity comes near 1e12 in its unit, nor below 1e-9 unless it is 0 (a denormal
    # acceleration made every move take forever): a last bound on what the checks above let by
    bad = bad_number_path(data, limit=1e12, tiny=1e-9)
    if bad is not None:
        raise RigConfigError(
            f"{source}: {bad}: must be a finite number, 0 or of magnitude in [1e-9, 1e12]"
        )
    return rig


def servo_ticks(j: JointConfig, angle_deg: float) -> float:
    """Joint angle (deg) -> Goal Position ticks before rounding (may be inf or NaN)."""
    servo_deg = (angle_deg - j.zero_offset_deg) * j.gear_ratio * j.direction
    return ct.CENTER_TICK + servo_deg * ct.TICKS_PER_REV / 360.0


def _check_joint(j: JointConfig, i: int, fail) -> None:
    """Consistency of one joint: limits ordered, every conversion fits its register.

    Comparisons are written ``not (ok)`` so that a NaN (impossible after :func:`non_finite`,
    but cheap to be sure of) refuses.
    """
    if not j.min_deg < j.max_deg:
        raise fail(("joints", i, "min_deg"), f"min_deg {j.min_deg} must be < max_deg {j.max_deg}")
    lo, hi = ct.POSITION_RANGE[ct.OPERATING_MODES[j.operating_mode]]
    for key in ("min_deg", "max_deg"):
        t = servo_ticks(j, getattr(j, key))
        if not (math.isfinite(t) and lo <= round(t) <= hi):
            raise fail(
                ("joints", i, key),
                f"{getattr(j, key)} deg is servo tick {t:.6g}, outside {lo}..{hi} of"
                f" {j.operating_mode} mode (check gear_ratio/zero_offset_deg)",
            )
    tol = j.settle_tolerance_deg
    if not (0.0 < tol <= j.max_deg - j.min_deg):
        raise fail(
            ("joints", i, "settle_tolerance_deg"),
            f"{tol} deg must be > 0 and within the joint's range ({j.max_deg - j.min_deg} deg)",
        )
    for key, unit, limit in (
        ("profile_velocity_deg_s", 60.0 / (360.0 * ct.VELOCITY_UNIT_RPM), ct.PROFILE_RAW_MAX),
        (
            "profile_acceleration_deg_s2",
            3600.0 / (360.0 * ct.ACCELERATION_UNIT_RPM2),
            ct.PROFILE_RAW_MAX,
        ),
    ):
        raw = getattr(j, key) * j.gear_ratio * unit
        # 0 in these registers means "no limit" to the servo: a speed too small to express
        # must not become the fastest one
        if not (math.isfinite(raw) and 1 <= round(raw) <= limit):
            raise fail(
                ("joints", i, key),
                f"{getattr(j, key)} at gear ratio {j.gear_ratio} is register value {raw:.6g},"
                f" outside 1..{limit}",
            )


def _outside_keepout(angle: float, k: Keepout) -> bool:
    return angle < k.min_deg or angle > k.max_deg


def _build(data: dict, text: str, source: str, check_sample_model: bool = True) -> RigConfig:
    def fail(path: tuple, msg: str) -> RigConfigError:
        return RigConfigError(f"{where(source, text, path)}: {msg}")

    joints = tuple(JointConfig(**j) for j in data["joints"])
    names: set[str] = set()
    ids: set[int] = set()
    for i, j in enumerate(joints):
        if j.name in names:
            raise fail(("joints", i, "name"), f"duplicate joint name {j.name!r}")
        if j.id in ids:
            raise fail(("joints", i, "id"), f"duplicate servo id {j.id}")
        names.add(j.name)
        ids.add(j.id)
        _check_joint(j, i, fail)
    layout = LayoutConfig(**data["layout"])
    for key in ("light", "camera", "tilt", "rotation"):
        if getattr(layout, key) not in names:
            raise fail(("layout", key), f"names no joint ({getattr(layout, key)!r})")
    if len({layout.light, layout.camera, layout.tilt, layout.rotation}) != 4:
        raise fail(
            ("layout", "light"), "light, camera, tilt and rotation must be four different joints"
        )
    park = {k: float(v) for k, v in data["park"].items()}
    for k, v in park.items():
        if k not in names:
            raise fail(("park", k), "names no joint")
        j = next(x for x in joints if x.name == k)
        if not j.min_deg <= v <= j.max_deg:  # NaN refuses
            raise fail(("park", k), f"{v} deg outside the joint limits [{j.min_deg}, {j.max_deg}]")
    s = dict(data["safety"])
    keep = []
    for i, k in enumerate(s.pop("keepout", [])):
        if k["joint"] not in names:
            raise fail(("safety", "keepout", i, "joint"), f"names no joint ({k['joint']!r})")
        if not k["min_deg"] < k["max_deg"]:
            raise fail(("safety", "keepout", i, "min_deg"), "min_deg must be < max_deg")
        ko = Keepout(**k)
        keep.append(ko)
        # the home angle decides which side of the sector the joint lives on (it may never
        # cross it): the park angle, or the servo's centre when [park] does not name the joint
        j = next(x for x in joints if x.name == ko.joint)
        if ko.joint in park:
            home, at = park[ko.joint], ("park", ko.joint)
        else:
            home, at = j.zero_offset_deg, ("safety", "keepout", i, "joint")
            if not j.min_deg <= home <= j.max_deg:
                raise fail(
                    at,
                    f"joint {ko.joint} has no park angle and its zero_offset_deg {home} is"
                    f" outside its limits: give it one in [park]",
                )
        if not _outside_keepout(home, ko):
            raise fail(
                at,
                f"home angle {home} deg of joint {ko.joint} is inside the keep-out sector"
                f" [{ko.min_deg}, {ko.max_deg}] ({ko.reason})",
            )
    safety = SafetyConfig(keepout=tuple(keep), **s)
    lay_l, lay_c = layout.light, layout.camera
    if lay_l in park and lay_c in park:
        sep = abs(math.remainder(park[lay_l] - park[lay_c], 360.0))
        if not sep >= safety.min_light_camera_deg:
            raise fail(
                ("park", lay_l),
                f"park pose puts the light and camera arms {sep} deg apart"
                f" (< safety.min_light_camera_deg {safety.min_light_camera_deg})",
            )
    sim = SimConfig(**data.get("sim", {}))
    if "sample" in data.get("sim", {}):
        from gonio.rigs.sim.truth import file_part, truth_file

        try:
            path = truth_file(sim.sample, source)
        except ValueError as exc:
            raise fail(("sim", "sample"), str(exc)) from None
        if path is None and check_sample_model:
            from gonio.brdf import models

            try:
                models.Node.from_dict(sim.sample)
            except Exception as exc:
                raise fail(("sim", "sample"), f"not a gonio model: {exc}") from None
        elif path is not None and not file_part(path).is_file():
            # the table itself is read when the camera opens, before any motion
            raise fail(("sim", "sample", "file"), f"no such file: {file_part(path)}")
    return RigConfig(
        name=data["name"],
        description=data.get("description", ""),
        bus=BusConfig(**data["bus"]),
        joints=joints,
        layout=layout,
        park_deg=park,
        safety=safety,
        camera=dict(data.get("camera", {})),
        light=dict(data.get("light", {})),
        sim=sim,
        source=source,
        text=text,
    )


def schema_json() -> str:
    """The schema as the text committed in ``data-schema/rig.schema.json`` (written by
    :mod:`gonio.io.schemas`, which :mod:`gonio.rigs.schema` registers it with)."""
    from gonio.io.schemas import render

    return render(rig_schema())


if __name__ == "__main__":  # pragma: no cover
    import sys

    if "--schema" in sys.argv:
        sys.stdout.write(schema_json())
