"""The emulator against the real dynamixel_sdk over a pseudo-terminal (conformance)."""

from __future__ import annotations

import os
import select
import time
import tty

import dynamixel_sdk as sdk
import pytest

from gonio.rigs import control_table as ct
from gonio.rigs import protocol as p
from gonio.rigs.sim import FaultConfig, ServoChainEmulator, ServoSpec


@pytest.fixture
def emu():
    e = ServoChainEmulator(
        [ServoSpec(1, "XM430-W350", 52), ServoSpec(2, "XL430-W250", 46, 1000)],
        time_scale=5.0,
        settle_ticks=0,
    )
    e.start()
    yield e
    e.stop()


@pytest.fixture
def sdk_port(emu):
    port = sdk.PortHandler(emu.port)
    assert port.openPort() and port.setBaudRate(1_000_000)
    yield port, sdk.PacketHandler(2.0)
    port.closePort()


def _retry(call, tries: int = 5) -> int:
    """A GroupSyncRead transaction, retried on a timeout: on a loaded machine a reply can miss
    the SDK's ~34 ms window; that is not a protocol failure (the driver retries too)."""
    for _ in range(tries):
        res = call()
        if res != sdk.COMM_RX_TIMEOUT:
            return res
    return res


def test_sdk_bytes_are_the_packets_we_decode():
    """What the SDK writes on the wire equals our encoder's packet, byte for byte."""
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        port = sdk.PortHandler(os.ttyname(slave))
        assert port.openPort()
        ph = sdk.PacketHandler(2.0)
        ph.write4ByteTxOnly(port, 1, 116, 512)
        grp = sdk.GroupSyncWrite(port, ph, 116, 4)
        grp.addParam(1, [150, 0, 0, 0])
        grp.addParam(2, [170, 0, 0, 0])
        grp.txPacket()
        time.sleep(0.02)
        select.select([master], [], [], 0.5)
        wire = os.read(master, 4096)
        port.closePort()
    finally:
        os.close(master)
        os.close(slave)
    expected = p.encode(1, p.WRITE, p.u16(116) + p.u32(512)) + p.encode(
        p.BROADCAST_ID,
        p.SYNC_WRITE,
        p.u16(116) + p.u16(4) + b"\x01" + p.u32(150) + b"\x02" + p.u32(170),
    )
    assert wire == expected


def test_ping_models_and_firmware(sdk_port):
    port, ph = sdk_port
    assert ph.ping(port, 1) == (ct.MODELS["XM430-W350"], sdk.COMM_SUCCESS, 0)
    assert ph.ping(port, 2)[0] == ct.MODELS["XL430-W250"]
    assert ph.read1ByteTxRx(port, 2, ct.FIRMWARE_VERSION[0])[0] == 46
    assert ph.ping(port, 3)[1] == sdk.COMM_RX_TIMEOUT
    found, res = ph.broadcastPing(port)
    assert res == sdk.COMM_SUCCESS
    assert found == {1: [1020, 52], 2: [1060, 46]}


def _ask(fn, *args):
    """A raw SDK transaction expecting a reply, retried on a timeout (loaded host)."""
    for _ in range(5):
        out = fn(*args)
        comm = out if isinstance(out, int) else (out[-2] if len(out) == 3 else out[0])
        if comm != sdk.COMM_RX_TIMEOUT:
            return out
    return out


def test_register_semantics(sdk_port):
    port, ph = sdk_port
    # EEPROM is writable with torque off, refused (access error) with torque on
    assert _ask(ph.write1ByteTxRx, port, 1, 11, 4) == (sdk.COMM_SUCCESS, 0)
    assert _ask(ph.read1ByteTxRx, port, 1, 11)[0] == 4
    assert _ask(ph.write1ByteTxRx, port, 1, 11, 3) == (sdk.COMM_SUCCESS, 0)
    assert _ask(ph.write1ByteTxRx, port, 1, 64, 1) == (sdk.COMM_SUCCESS, 0)
    assert _ask(ph.write1ByteTxRx, port, 1, 11, 4)[1] == sdk.ERRNUM_ACCESS
    # goal beyond the position limits -> data limit error, and nothing moves
    assert _ask(ph.write4ByteTxRx, port, 1, 116, 5000)[1] == sdk.ERRNUM_DATA_LIMIT
    assert _ask(ph.read4ByteTxRx, port, 1, 132)[0] == 2048
    # unknown instruction -> instruction error
    assert _ask(ph.action, port, 1) == sdk.COMM_SUCCESS  # action expects no status by SDK design


def test_motion_follows_profile_and_group_sync_read(sdk_port, emu):
    port, ph = sdk_port
    for sid in (1, 2):
        ph.write4ByteTxRx(port, sid, 108, 20)
        ph.write4ByteTxRx(port, sid, 112, 100)
        ph.write1ByteTxRx(port, sid, 64, 1)
    sw = sdk.GroupSyncWrite(port, ph, 116, 4)
    sw.addParam(1, list((3000).to_bytes(4, "little")))
    sw.addParam(2, list((1500).to_bytes(4, "little")))
    assert sw.txPacket() == sdk.COMM_SUCCESS
    v = ct.velocity_raw_to_deg_s(100) * 4096 / 360
    a = ct.acceleration_raw_to_deg_s2(20) * 4096 / 360
    # the profile, then the emulated ringing (0.12 s simulated) while Moving stays 1
    expect_T = (ct.trapezoid_time(952, v, a) + 0.12) / emu.time_scale
    sr = sdk.GroupSyncRead(port, ph, 122, 1)
    sr.addParam(1)
    sr.addParam(2)
    t0 = time.monotonic()
    saw_moving = stopped = False
    while time.monotonic() - t0 < 2.0:
        assert _retry(sr.txRxPacket) == sdk.COMM_SUCCESS
        if sr.getData(1, 122, 1):
            saw_moving = True
        elif saw_moving:
            stopped = True
            break
    elapsed = time.monotonic() - t0
    assert saw_moving and stopped
    # never done before the profile allows; how late a loaded machine observes it is not tested
    assert elapsed >= 0.8 * expect_T
    pos = sdk.GroupSyncRead(port, ph, 132, 4)
    pos.addParam(1)
    pos.addParam(2)
    time.sleep(0.05)
    assert _retry(pos.txRxPacket) == sdk.COMM_SUCCESS
    assert pos.getData(1, 132, 4) == 3000
    assert pos.getData(2, 132, 4) == 1500
    assert [(g.id, g.ticks) for g in emu.goal_log] == [(1, 3000), (2, 1500)]


def test_overload_sets_alert_bit_and_torque_off_until_reboot(sdk_port, emu):
    port, ph = sdk_port
    _ask(ph.write1ByteTxRx, port, 1, 64, 1)
    emu.overload(1)
    hw, res, err = _ask(ph.read1ByteTxRx, port, 1, 70)
    assert res == sdk.COMM_SUCCESS and hw & ct.HW_OVERLOAD and err & sdk.ERRBIT_ALERT
    assert _ask(ph.read1ByteTxRx, port, 1, 64)[0] == 0
    assert _ask(ph.write1ByteTxRx, port, 1, 64, 1)[1] == sdk.ERRNUM_RESULT_FAIL | sdk.ERRBIT_ALERT
    assert _ask(ph.reboot, port, 1) == (sdk.COMM_SUCCESS, 0)
    assert _ask(ph.read1ByteTxRx, port, 1, 70)[:3:2] == (0, 0)
    assert _ask(ph.write1ByteTxRx, port, 1, 64, 1) == (sdk.COMM_SUCCESS, 0)


def test_dead_servo_and_crc_faults(sdk_port, emu):
    port, ph = sdk_port

    def ping(sid):
        # a reply can miss the SDK's ~34 ms window on a loaded machine: retry timeouts only
        # where an answer is expected
        for _ in range(5):
            out = ph.ping(port, sid)
            if out[1] != sdk.COMM_RX_TIMEOUT:
                return out
        return out

    emu.kill(2, 0.3)
    assert ph.ping(port, 2)[1] == sdk.COMM_RX_TIMEOUT
    time.sleep(0.35)
    assert ping(2)[1] == sdk.COMM_SUCCESS
    emu.faults = FaultConfig(crc=1.0)
    _, res, err = ping(1)
    assert res == sdk.COMM_SUCCESS and err == p.ERR_CRC
    emu.faults = FaultConfig(garble=1.0)
    assert ph.ping(port, 1)[1] in (sdk.COMM_RX_CORRUPT, sdk.COMM_RX_TIMEOUT)
    emu.faults = FaultConfig(drop=1.0)
    assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT


def test_moving_status_profile_then_ringing_then_in_position():
    # Simulated time runs at a quarter of wall time so that the 0.12 s ringing phase lasts
    # 0.48 s of wall time: polls on a loaded machine can take tens of milliseconds each.
    with ServoChainEmulator([ServoSpec(1)], time_scale=0.25, settle_ticks=0) as emu:
        port = sdk.PortHandler(emu.port)
        port.openPort()
        ph = sdk.PacketHandler(2.0)
        _ask(ph.write4ByteTxRx, port, 1, 108, 100)
        _ask(ph.write4ByteTxRx, port, 1, 112, 200)
        _ask(ph.write1ByteTxRx, port, 1, 64, 1)
        _ask(ph.write4ByteTxRx, port, 1, 116, 2148)
        seen = []
        t0 = time.monotonic()
        while time.monotonic() - t0 < 10.0:
            status = _ask(ph.read1ByteTxRx, port, 1, 123)[0]
            moving = _ask(ph.read1ByteTxRx, port, 1, 122)[0]
            seen.append((bool(status & 2), bool(moving), bool(status & 1)))
            if not moving and seen[-1][2]:
                break
        port.closePort()
        # phases in order: profile ongoing -> ringing (moving, profile over) -> in position
        assert seen[0] == (True, True, False)
        assert (False, True, False) in seen
        assert seen[-1] == (False, False, True)
        assert emu.register(1, ct.PRESENT_POSITION) == 2148


def test_emulator_answers_manual_examples_byte_for_byte():
    """The e-Manual's instruction packets, sent raw, get the e-Manual's status packets back."""
    from tests.rigs.test_protocol import golden

    specs = [ServoSpec(1, "XM430-W210", 38, 166), ServoSpec(2, "XM430-W210", 38, 2079)]
    with ServoChainEmulator(specs, time_scale=50.0, settle_ticks=0) as emu:
        fd = os.open(emu.port, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)

        def exchange(raw: bytes, expect_len: int, wait: float = 1.0) -> bytes:
            os.write(fd, raw)
            got = b""
            t0 = time.monotonic()
            while len(got) < expect_len and time.monotonic() - t0 < wait:
                r, _, _ = select.select([fd], [], [], 0.05)
                if r:
                    got += os.read(fd, 256)
            return got

        try:
            assert exchange(golden("ping id1"), 14) == golden("ping status model 1030 fw 38")
            assert exchange(golden("read present position id1"), 15) == golden("read status 166")
            both = golden("read status 166") + golden("sync read status id2 2079")
            assert exchange(golden("sync read 132x4 ids 1 2"), 30) == both
            assert exchange(golden("write goal 512 id1"), 11) == golden("empty status id1")
            assert exchange(golden("reboot id1"), 11) == golden("empty status id1")
            # sync write has no reply; its effect is visible in the registers
            assert exchange(golden("sync write 116 ids 1=150 2=170"), 1, 0.1) == b""
            assert emu.register(1, ct.GOAL_POSITION) == 150
            assert emu.register(2, ct.GOAL_POSITION) == 170
        finally:
            os.close(fd)


def test_byte_stuffing_both_ways_through_the_sdk(sdk_port, emu):
    """A register value whose bytes contain FF FF FD is stuffed by the SDK on the way in and by
    the emulator on the way out; both sides unstuff it to the same value."""
    port, ph = sdk_port
    value = int.from_bytes(b"\xff\xff\xfd\x00", "little")
    assert ph.write4ByteTxRx(port, 1, ct.HOMING_OFFSET[0], value) == (sdk.COMM_SUCCESS, 0)
    assert emu.register(1, ct.HOMING_OFFSET) == value
    got, res, err = ph.read4ByteTxRx(port, 1, ct.HOMING_OFFSET[0])
    assert (got, res, err) == (value, sdk.COMM_SUCCESS, 0)
    # and the status packet on the wire really carries the stuffing byte
    raw = p.status_packet(1, 0, value.to_bytes(4, "little"))
    assert b"\xff\xff\xfd\xfd" in raw


def test_settle_error_is_deterministic_per_goal_and_bounded():
    specs = [ServoSpec(1, initial_position=1000)]
    with ServoChainEmulator(specs, time_scale=100.0, settle_ticks=3, seed=5) as emu:
        port = sdk.PortHandler(emu.port)
        port.openPort()
        ph = sdk.PacketHandler(2.0)
        _ask(ph.write1ByteTxRx, port, 1, 64, 1)
        ends = {}
        for goal in (1500, 2500, 1500, 2500):
            _ask(ph.write4ByteTxRx, port, 1, 116, goal)
            while _ask(ph.read1ByteTxRx, port, 1, 122)[0]:
                pass
            end = _ask(ph.read4ByteTxRx, port, 1, 132)[0]
            assert abs(end - goal) <= 3
            assert ends.setdefault(goal, end) == end
        port.closePort()
