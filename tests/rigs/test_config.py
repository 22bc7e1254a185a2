"""Rig files: shipped rigs load, the committed schema is the generated one, bad files fail well."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from gonio.errors import RigConfigError
from gonio.rigs.config import load_rig, parse_rig, rig_schema, schema_json, shipped_rigs

ROOT = Path(__file__).resolve().parents[2]


def sim_text() -> str:
    from importlib import resources

    return resources.files("gonio.rigs").joinpath("sim.toml").read_text()


def test_shipped_rigs_load():
    assert {"sim", "xm430_4axis"} <= set(shipped_rigs())
    sim = load_rig("sim")
    assert sim.is_sim and len(sim.joints) == 4
    hw = load_rig("xm430_4axis")
    assert not hw.is_sim and hw.joint("light_arm").gear_ratio == 3.0


def test_committed_schema_matches_code():
    committed = (ROOT / "data-schema" / "rig.schema.json").read_text()
    assert committed == schema_json()
    assert json.loads(committed)["required"] == rig_schema()["required"]


def test_tick_conversion_roundtrip_with_gear_and_direction():
    j = load_rig("xm430_4axis").joint("camera_arm")
    for a in (-100.0, 0.0, 33.3, 150.0):
        assert abs(j.from_ticks(j.to_ticks(a)) - a) <= 360 / 4096 / j.gear_ratio / 2 + 1e-12


TAIL = (
    'operating_mode = "position"\ngear_ratio = 1.0\nzero_offset_deg = 0.0\ndirection = 1\n'
    "min_deg = -179.0"
)


def _line_of(text: str, needle: str) -> int:
    # the last line containing needle (the edited key is the later of two equal lines)
    return max(i + 1 for i, l in enumerate(text.splitlines()) if needle in l)


@pytest.mark.parametrize(
    ("old", "new", "key", "needle"),
    [
        ("baudrate = 1000000", "baudrate = 1234", "bus.baudrate", "baudrate = 1234"),
        ("max_deg = 85.0", 'max_deg = "85"', "joints[2].max_deg", 'max_deg = "85"'),
        (
            'settle_tolerance_deg = 0.3\n\n[[joints]]\nname = "tilt"',
            'settle_tolerance_deg = 0.3\nspeed = 3\n\n[[joints]]\nname = "tilt"',
            "joints[1].speed",
            "speed = 3",
        ),
        ('camera = "camera_arm"', 'camera = "cam"', "layout.camera", 'camera = "cam"'),
        (
            "min_light_camera_deg = 8.0",
            "min_light_camera_deg = 200.0",
            "safety.min_light_camera_deg",
            "min_light_camera_deg = 200.0",
        ),
        ("tilt = 0.0\nturntable = 0.0", "tilt = 99.0\nturntable = 0.0", "park.tilt", "tilt = 99.0"),
        ("id = 4", "id = 3", "joints[3].id", "id = 3"),
        ("min_deg = -85.0", "min_deg = 90.0", "joints[2].min_deg", "min_deg = 90.0"),
        (
            'model = "XM430-W350"\n' + TAIL,
            'model = "XM999"\n' + TAIL,
            "joints[3].model",
            'model = "XM999"',
        ),
    ],
)
def test_bad_rig_files_name_key_and_line(old, new, key, needle):
    text = sim_text()
    assert old in text, old
    bad = text.replace(old, new, 1)
    with pytest.raises(RigConfigError) as exc:
        parse_rig(bad, "bad.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert key in msg, msg
    needle_line = _line_of(bad, needle)
    assert re.match(rf"bad\.toml:{needle_line}: ", msg), (msg, needle_line)


def test_missing_required_key_and_bad_toml():
    text = sim_text().replace('port = "sim"\n', "")
    with pytest.raises(RigConfigError, match=r"missing required key bus\.port"):
        parse_rig(text, "x.toml")
    with pytest.raises(RigConfigError, match=r"x\.toml: invalid TOML"):
        parse_rig("name = [", "x.toml")
    with pytest.raises(RigConfigError, match="not found"):
        load_rig("/nonexistent/rig.toml")
    with pytest.raises(RigConfigError, match="unknown rig"):
        load_rig("nope")


def test_bad_sim_sample_model():
    text = sim_text().replace('type = "Phong"', 'type = "NoSuchModel"')
    with pytest.raises(RigConfigError, match=r"sim\.sample"):
        parse_rig(text, "x.toml")
