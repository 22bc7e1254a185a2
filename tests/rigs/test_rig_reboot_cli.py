"""``gonio rig check`` reports a latched hardware error with the next step; ``gonio rig reboot``
clears it, and nothing else does (an emulator on a pseudo-terminal named by a rig file)."""

from __future__ import annotations

import json

from gonio.cli import main
from gonio.rigs import control_table as ct
from gonio.rigs.config import load_rig
from gonio.rigs.protocol import REBOOT
from gonio.rigs.session import make_emulator

RIG = load_rig("sim")


def test_check_reports_a_latch_and_reboot_clears_it(tmp_path, capsys):
    with make_emulator(RIG) as emu:
        rig = tmp_path / "pty.toml"
        rig.write_text(RIG.text.replace('\nport = "sim"', f'\nport = "{emu.port}"', 1))
        emu.hardware_error(2, ct.HW_OVERHEATING)
        assert main(["rig", "check", "--rig", str(rig), "--json"]) == 3
        out = capsys.readouterr()
        report = json.loads(out.out)
        cam = next(s for s in report["servos"] if s["joint"] == "camera_arm")
        assert cam["hardware_error"] == ct.HW_OVERHEATING and cam["alert"] is True
        assert cam["hardware_error_text"] == "overheating" and not report["ok"]
        (line,) = out.err.strip().splitlines()
        assert "camera_arm (id 2): overheating" in line and "next: Let the servo cool" in line
        assert not [r for r in emu.packet_log if r.instruction == REBOOT]  # check only reads
        assert main(["rig", "reboot", "--rig", str(rig)]) == 0
        out = capsys.readouterr().out
        assert "rebooted servo 2 (camera_arm): overheating cleared, torque off" in out
        assert [r.id for r in emu.packet_log if r.instruction == REBOOT] == [2]
        assert emu.register(2, ct.HARDWARE_ERROR_STATUS) == 0
        assert main(["rig", "check", "--rig", str(rig)]) == 0
        assert main(["rig", "reboot", "--rig", str(rig)]) == 0
        assert "nothing rebooted" in capsys.readouterr().out
        assert emu.goal_log == []  # nothing ever moved
