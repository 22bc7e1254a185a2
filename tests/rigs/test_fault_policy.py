"""The policy table of servo faults: complete, and the guide shows the code's table."""

from __future__ import annotations

import re
from pathlib import Path

from gonio.rigs import control_table as ct
from gonio.rigs.faults import POLICY, bit_policies, policy, policy_markdown

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide" / "rig.md"


def test_every_fault_has_one_row_and_every_row_stops_the_run():
    keys = [p.key for p in POLICY]
    assert len(keys) == len(set(keys))
    assert set(keys) == {*ct.HW_ERROR_NAMES.values(), "stall", "latch at open", "bus lost"}
    for bit, name in ct.HW_ERROR_NAMES.items():
        (row,) = bit_policies(bit)
        assert row.key == name and row.bit == bit
    assert all(p.stops_run and p.next_step for p in POLICY)
    assert "reboot" not in policy("stall").next_step  # a blocked joint has nothing latched


def test_the_guide_shows_the_code_s_policy_table():
    text = GUIDE.read_text(encoding="utf-8")
    m = re.search(r"<!-- policy:faults -->\n(.*?)\n<!-- /policy:faults -->", text, re.S)
    assert m, f"{GUIDE} has no <!-- policy:faults --> section"
    assert m.group(1) == policy_markdown(), (
        "docs/guide/rig.md's fault table differs from gonio.rigs.faults.POLICY: paste"
        " `python -c 'from gonio.rigs.faults import policy_markdown as m; print(m())'`"
    )
