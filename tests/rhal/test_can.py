"""The can:// driver at the wire, against drive and base emulators on python-can's virtual bus.

There is no vcan here, so both sides open python-can's in-process ``virtual`` interface on the
same channel: every frame the driver sends reaches the emulator's own bus handle, which decodes
it with a library of its own (a canopen LocalNode for the CiA 402 drives, cantools for the DBC
base), and the other way round. One test runs the base over ``udp_multicast`` on an IPv6
interface-local group, which never leaves the computer.
"""

import asyncio
import json
import math
import struct
import time

import can
import canopen
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rhal
from rhal import NotSupportedError, RobotConnectionError
from rhal.canbus import CanRobot, parse_url
from rhal.options import driver_options
from tests.rhal.can_emulator import Cia402BaseEmulator, Cia402Drive, DbcBaseEmulator
from tests.waiting import DEADLINE, starve, until

COUNTS_PER_METRE = 4096 / (math.pi * 0.2)  # the emulator's defaults: 4096 counts, 0.2 m wheel
TRACK = 0.4
#: SYNC at 50 Hz and heartbeats at 20 Hz: a quicker walk up the state machine.
QUICK = {"sync": 0.02, "heartbeat": 0.05}


async def failing(call):
    """The RobotConnectionError ``call()`` raises, or None while it succeeds."""
    try:
        await call()
    except RobotConnectionError as exc:
        return exc
    return None


@pytest.fixture
async def base():
    emu = Cia402BaseEmulator(**QUICK)
    await emu.start()
    yield emu
    await emu.stop()


@pytest.fixture
async def robot(base):
    bot = rhal.connect(base.url)
    await bot.open()
    yield bot
    await bot.close()


@pytest.fixture
async def dbc_base():
    emu = DbcBaseEmulator()
    await emu.start()
    yield emu
    await emu.stop()


@pytest.fixture
async def dbc_robot(dbc_base):
    async with rhal.connect(dbc_base.url) as bot:
        yield bot


def wheel_targets(linear, angular):
    """The target velocities (counts/s) each drive should get, right wheel mirrored."""
    left = round((linear - angular * TRACK / 2) * COUNTS_PER_METRE)
    right = -round((linear + angular * TRACK / 2) * COUNTS_PER_METRE)
    return left, right


# -- URL and options, no I/O -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("url", "interface", "channel"),
    [("can://", "socketcan", "can0"),
     ("can://socketcan/can1", "socketcan", "can1"),
     ("can://slcan/dev/ttyACM0", "slcan", "/dev/ttyACM0"),
     ("can://slcan/COM3", "slcan", "COM3"),
     ("can://virtual/robot0", "virtual", "robot0"),
     ("can://udp_multicast/239.74.163.2", "udp_multicast", "239.74.163.2"),
     ("can://udp_multicast/ff11::7268:616c", "udp_multicast", "ff11::7268:616c"),
     ("CAN://PCAN/PCAN_USBBUS1", "pcan", "PCAN_USBBUS1"),
     ("can://kvaser", "kvaser", None)],
)  # fmt: skip
def test_url_names_interface_and_channel(url, interface, channel):
    assert parse_url(url) == (interface, channel)
    bot = CanRobot(url)
    assert (bot.interface, bot.channel) == (interface, channel)


def test_an_empty_url_constructs_a_cia402_base_without_io():
    bot = rhal.connect("can://")
    assert (bot.interface, bot.channel, bot.profile) == ("socketcan", "can0", "cia402")
    assert not bot.is_open and bot.bitrate == 500000
    specs = bot.capabilities()["sensors"]
    assert set(specs) == {"position", "velocity", "heading", "wheels", "drives", "errors"}
    dbc = rhal.connect("can://?profile=dbc&range=BaseStatus.Range")
    assert set(dbc.capabilities()["sensors"]) == {
        "position", "velocity", "heading", "range", "signals", "errors",
    }  # fmt: skip
    assert dbc.capabilities()["sensors"]["range"]["max"] == 10.0


def test_url_options_reach_the_driver():
    bot = rhal.connect(
        "can://socketcan/can0?left=5&right=6&track=0.5&counts_per_metre=1000&invert_right=false"
        "&heartbeat=0.2&timeout=1&sync=0.01&bitrate=250000"
    )
    profile = bot._profile
    assert profile.nodes == {"left": 5, "right": 6}
    assert (profile.track, profile.counts_per_metre, profile.velocity_per_mps) == (0.5, 1000, 1000)
    assert profile.signs == {"left": 1, "right": 1}
    assert (profile.heartbeat, bot.timeout, profile.sync, bot.bitrate) == (0.2, 1.0, 0.01, 250000)


@pytest.mark.parametrize(
    ("url", "message"),
    [("can://nosuchcan/x", "unknown python-can interface 'nosuchcan'"),
     ("can://?profile=lin", "unknown CAN profile 'lin'"),
     ("can://?left=3&right=3", "left and right must be different"),
     ("can://?left=128", "node id from 1 to 127"),
     ("can://?track=0", "track must be greater than 0"),
     ("can://?invert_right=maybe", "invert_right must be true or false"),
     ("can://?heartbeat=0.5&timeout=0.5", "must be longer than the heartbeat"),
     ("can://?bitrate=-1", "bitrate"),
     ("can://?eds=/no/such/drive.eds", "cannot read the EDS file"),
     ("can://?profile=dbc&dbc=/no/such/base.dbc", "cannot load the DBC file"),
     ("can://?profile=dbc&command=Nope", "has no message 'Nope' \\(command=\\); its messages are: "
                                         "BaseCommand, BaseFeedback, BaseStatus"),
     ("can://?profile=dbc&speed=BaseCommand.Nope", "has no signal 'Nope' \\(speed=\\)"),
     ("can://?profile=dbc&feedback_turn=Gone.TurnRate", "has no message 'Gone'"),
     ("can://?profile=dbc&speed=BaseFeedback.Speed", "must be a signal of the command message"),
     ("can://?profile=dbc&heading=Heading", "heading must name a signal as Message.Signal"),
     ("can://?profile=dbc&battery=BaseFeedback.Speed", "is in 'm/s'; battery signals must be"),
     ("can://?profile=dbc&rate=-1", "rate must be a number")],
)  # fmt: skip
def test_bad_options_are_clear_errors(url, message):
    with pytest.raises(ValueError, match=message):
        rhal.connect(url)


def test_an_option_of_the_other_profile_is_refused():
    with pytest.raises(ValueError, match="dbc is an option of the dbc profile; .* is cia402"):
        rhal.connect("can://?dbc=/tmp/base.dbc")
    with pytest.raises(ValueError, match="left is an option of the cia402 profile"):
        rhal.connect("can://?profile=dbc&left=3")
    rhal.connect("can://?profile=dbc&left=1&heading=")  # defaults and blanks are no choice
    with pytest.raises(TypeError, match="wheels"):
        rhal.connect("can://?wheels=4")


def test_every_option_is_typed_and_explained():
    options = {option.name: option for option in driver_options("can://")}
    assert {"profile", "left", "right", "dbc", "speed", "feedback_turn", "rate"} <= set(options)
    assert all(option.help for option in options.values())
    assert options["profile"].choices == ("cia402", "dbc")


def test_an_eds_without_the_402_objects_is_refused(tmp_path):
    eds = tmp_path / "io.eds"
    eds.write_text(
        "[DeviceInfo]\nProductName=An I/O module\n\n"
        "[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\n"
        "AccessType=ro\nDefaultValue=0x00000191\n"
    )
    with pytest.raises(ValueError, match="lacks objects the cia402 profile needs: .*0x6040"):
        rhal.connect(f"can://?eds={eds}")


def test_a_broken_dbc_is_refused(tmp_path):
    dbc = tmp_path / "broken.dbc"
    dbc.write_text("BO_ 1 Broken: 8 Host\n SG_ this is not a signal\n")
    with pytest.raises(ValueError, match="cannot load the DBC file"):
        rhal.connect(f"can://?profile=dbc&dbc={dbc}")


# -- cia402: bringing the drives up ----------------------------------------------------------


async def test_open_brings_both_drives_to_operation_enabled(robot, base):
    for drive in base.drives.values():
        assert drive.nmt_state == "OPERATIONAL"
        assert drive.state == "OPERATION ENABLED" and drive.mode == 3
        assert drive.heartbeat_ms() == 50  # the heartbeat option, in ms
        # The mapping the driver wrote over SDO, read back from the drive's own dictionary.
        assert drive.pdo_objects("rpdo", 1) == [0x6040, 0x60FF]
        assert drive.pdo_objects("rpdo", 2) == []
        assert drive.pdo_objects("tpdo", 1) == [0x6041, 0x6061]
        assert drive.pdo_objects("tpdo", 2) == [0x6064, 0x606C]
        assert drive.transmission_type(1) == drive.transmission_type(2) == 1  # every SYNC
        assert drive.tpdos_sent > 0
        # Shutdown, switch on, enable operation: the standard's walk, no step skipped.
        walk = [r.controlword for r in drive.received if r.controlword is not None]
        steps = [word for i, word in enumerate(walk) if i == 0 or walk[i - 1] != word]
        assert steps[:3] == [0x06, 0x07, 0x0F]
        assert drive.target == 0
    readings = await robot.sensors()
    for side, node in (("left", 1), ("right", 2)):
        assert readings["drives"][side] == {
            "node": node, "state": "OPERATION ENABLED", "mode": 3, "fault": None,
        }  # fmt: skip
    assert robot.connected and readings["errors"] == 0


async def test_open_fails_clearly_when_no_drive_answers():
    bot = CanRobot("can://virtual/rhal-can-nobody-home")
    with pytest.raises(RobotConnectionError, match=r"no answer from the left drive \(node 1\)"):
        await bot.open()
    assert not bot.is_open


async def test_a_device_that_is_not_a_402_drive_is_refused(base):
    base.left.node.data_store[0x1000] = {0: (0x00000191).to_bytes(4, "little")}  # CiA 401 I/O
    with pytest.raises(RobotConnectionError, match="left drive .* is not a CiA 402 drive"):
        await rhal.connect(base.url).open()


async def test_a_fault_that_stays_fails_open_with_the_fault(base):
    base.left.fault(0x4310, sticky=True)  # over-temperature that a reset cannot clear
    with pytest.raises(
        RobotConnectionError,
        match=r"left drive \(node 1\) did not reach OPERATION ENABLED: it stays in FAULT "
        r"\(Code 0x4310, Temperature\)",
    ):
        await rhal.connect(base.url).open()
    resets = [r.controlword for r in base.left.received if r.controlword == 0x80]
    assert resets, "the driver tried a fault reset"


async def test_open_resets_a_fault_that_has_cleared(base):
    base.right.fault(0x2310)
    async with rhal.connect(base.url) as bot:
        assert base.right.state == "OPERATION ENABLED" and base.right.error_code == 0
        assert 0x80 in [r.controlword for r in base.right.received]
        assert (await bot.sensors())["drives"]["right"]["fault"] is None


# -- cia402: motion --------------------------------------------------------------------------


@pytest.mark.parametrize(("linear", "angular"), [(0.3, 0.0), (0.0, 1.0), (0.2, -0.5), (-0.1, 1.5)])
async def test_drive_sets_each_wheel_target_velocity_with_its_sign(robot, base, linear, angular):
    left, right = wheel_targets(linear, angular)
    await robot.drive(linear, angular)
    await until(lambda: (base.left.target, base.right.target) == (left, right))
    for drive in base.drives.values():
        last = drive.received[-1]
        assert (last.via, last.controlword) == ("rpdo", 0x0F)
        assert drive.velocity == drive.target, "the drive turns: enabled, mode 3, no halt"
    assert base.commanded() == pytest.approx((linear, angular), abs=1e-3)


def test_wheel_targets_by_hand():
    # 0.5 m/s on a 0.2 m wheel with 4096 counts a turn: 0.5 / (0.2 pi) * 4096 = 3259.5 counts/s
    assert wheel_targets(0.5, 0.0) == (3259, -3259)
    assert wheel_targets(0.0, 1.0) == (-1304, -1304)  # spinning left: both wheels backwards


async def test_speeds_are_clamped_before_the_wire(base):
    async with rhal.connect(base.url, max_linear=0.2, max_angular=0.5) as bot:
        assert await bot.drive(1.0, -3.0) == {"linear": 0.2, "angular": -0.5}
        left, right = wheel_targets(0.2, -0.5)
        await until(lambda: (base.left.target, base.right.target) == (left, right))


async def test_stop_sends_halt_and_zero_to_both_drives_every_call(robot, base):
    await robot.drive(0.3, 0.0)
    await until(lambda: base.left.velocity != 0 and base.right.velocity != 0)
    stops = base.stops
    for count in range(1, 4):  # stopped already after the first: it goes on the wire anyway
        await robot.stop()
        await until(lambda count=count: base.stops == stops + count)
        for drive in base.drives.values():
            assert (drive.received[-1].controlword, drive.received[-1].target) == (0x10F, 0)
            assert drive.velocity == 0 and drive.state == "OPERATION ENABLED"
    assert base.commanded() == (0.0, 0.0)
    await robot.drive(0.1, 0.0)  # the halt is only until the next drive()
    await until(lambda: base.left.velocity == wheel_targets(0.1, 0.0)[0])


async def test_close_halts_then_switches_the_drives_off(base):
    async with rhal.connect(base.url) as bot:
        await bot.drive(0.2, 0.0)
        await until(lambda: base.left.velocity != 0)
    for drive in base.drives.values():
        await until(lambda drive=drive: drive.state == "READY TO SWITCH ON")
        last = [(r.controlword, r.target) for r in drive.received[-2:]]
        assert last == [(0x10F, 0), (0x06, 0)]
        await until(lambda drive=drive: drive.nmt_state == "PRE-OPERATIONAL")
        assert drive.velocity == 0


# -- cia402: readings ------------------------------------------------------------------------


async def test_velocity_comes_from_the_drives_velocity_actual(robot, base):
    await robot.drive(0.3, 0.5)

    def moving(readings):
        return readings["velocity"]["linear"] > 0.29

    readings = await until(lambda: _when(robot, moving))
    assert readings["velocity"] == pytest.approx({"linear": 0.3, "angular": 0.5}, abs=1e-3)
    assert readings["wheels"] == pytest.approx({"left": 0.2, "right": 0.4}, abs=1e-3)


async def test_odometry_follows_the_position_actual_counts(robot, base):
    async def moved(left_metres, right_metres, pose):
        base.turn_wheels(left_metres, right_metres)  # by hand: the drives are idle
        x, y, theta = pose

        def there(readings):
            position = readings["position"]
            return position == pytest.approx({"x": x, "y": y, "theta": theta}, abs=1e-3)

        return await until(lambda: _when(robot, there))

    await moved(1.0, 1.0, (1.0, 0.0, 0.0))
    quarter = math.pi / 2 * TRACK / 2  # each wheel's travel for a quarter turn on the spot
    readings = await moved(-quarter, quarter, (1.0, 0.0, math.pi / 2))
    assert readings["heading"] == pytest.approx(0.0, abs=0.1)  # facing north
    await moved(0.5, 0.5, (1.0, 0.5, math.pi / 2))
    await moved(quarter, -quarter, (1.0, 0.5, 0.0))


async def test_odometry_survives_the_32_bit_counter_wrap():
    emu = Cia402BaseEmulator(**QUICK)
    emu.left.position = 2**31 - 100.0  # about to wrap forwards
    emu.right.position = -(2**31) + 100.0  # mirrored: about to wrap backwards
    await emu.start()
    try:
        async with rhal.connect(emu.url) as bot:
            metres = 200 / COUNTS_PER_METRE
            emu.turn_wheels(metres, metres)
            # Within 2 mm: a wheel whose TPDO a loaded machine held past the other's SYNC makes
            # the move an arc there and back (1.2 mm aside); a wrong wrap is 658 km off.
            near = pytest.approx(metres, abs=2e-3)
            await until(lambda: _when(bot, lambda r: r["position"]["x"] == near))
            assert (await bot.sensors())["position"]["y"] == pytest.approx(0.0, abs=2e-3)
    finally:
        await emu.stop()


async def test_readings_are_json_and_match_capabilities(robot):
    readings = await robot.sensors()
    assert json.loads(json.dumps(readings)) == readings
    assert set(readings) == set(robot.capabilities()["sensors"])
    with pytest.raises(NotSupportedError, match="no sensor 'range'"):
        await robot.sensor("range")


# -- cia402: faults --------------------------------------------------------------------------


async def test_a_drive_fault_is_reported_and_refuses_motion(robot, base):
    base.left.fault(0x2310)

    def faulted(readings):
        return readings["drives"]["left"]["fault"]

    readings = await until(lambda: _when(robot, faulted))
    assert readings["drives"]["left"]["state"] == "FAULT"
    assert readings["drives"]["left"]["fault"] == "Code 0x2310, Current"
    assert readings["drives"]["right"]["state"] == "OPERATION ENABLED"
    with pytest.raises(
        RobotConnectionError,
        match=r"the left drive \(node 1\) of the CAN base .* is in FAULT \(Code 0x2310, Current\)"
        r", not OPERATION ENABLED; close and open the robot",
    ):
        await robot.drive(0.2, 0.0)
    stops = base.stops
    await robot.stop()  # an e-stop still goes out, to the drive that can move too
    await until(lambda: base.stops == stops + 1)
    await robot.close()
    await robot.open()  # a new session resets the fault
    assert base.left.state == "OPERATION ENABLED"
    await robot.drive(0.2, 0.0)
    await until(lambda: base.left.velocity != 0)


async def test_heartbeat_loss_is_a_clear_error_until_the_drive_returns(robot, base):
    await robot.drive(0.2, 0.0)
    await until(lambda: base.left.velocity != 0)
    await asyncio.to_thread(base.right.unplug)

    error = await until(lambda: failing(robot.sensors))
    assert str(error).startswith(f"no link to the CAN base at {base.url!r}")
    assert "no heartbeat from the right drive (node 2) for 0.5 s); reconnecting" in str(error)
    with pytest.raises(RobotConnectionError, match="no link"):
        await robot.drive(0.2, 0.0)
    with pytest.raises(RobotConnectionError, match="no link"):
        await robot.stop()
    # The drive that still heard the driver was stopped when the link was lost.
    await until(lambda: base.left.velocity == 0)

    await asyncio.to_thread(base.right.start)  # powered again: PRE-OPERATIONAL, not enabled
    await until(lambda: robot.connected)
    assert base.right.state == "OPERATION ENABLED" and base.right.boots == 2
    assert base.commanded() == (0.0, 0.0), "motion does not resume by itself"
    await robot.drive(-0.1, 0.0)
    await until(lambda: base.right.velocity == wheel_targets(-0.1, 0.0)[1])


async def test_a_driver_starved_of_the_cpu_keeps_the_drives(robot, base):
    """A busy machine can leave the whole process, drives and driver alike, asleep for
    longer than the heartbeat timeout: that is not a drive gone (on a loaded machine the link
    was dropped, the drives stopped and brought up again)."""
    await robot.drive(0.2, 0.0)
    await until(lambda: base.left.velocity != 0)
    stops, sent = base.stops, base.left.tpdos_sent
    starve(3 * 0.5)  # three heartbeat timeouts
    await until(lambda: base.left.tpdos_sent > sent + 20)  # the bus talks again, and is heard
    assert robot.connected and base.stops == stops
    assert base.left.velocity != 0  # the program's motion goes on


async def test_a_drive_that_restarts_is_brought_up_again(robot, base):
    def restart():
        base.right.unplug()
        base.right.start()  # boots within the heartbeat timeout: the boot-up message tells

    await asyncio.to_thread(restart)
    await until(lambda: base.right.state == "OPERATION ENABLED")
    await until(lambda: robot.connected)
    await robot.drive(0.1, 0.0)
    await until(lambda: base.right.velocity == wheel_targets(0.1, 0.0)[1])


async def test_closing_with_the_link_lost_still_works(base):
    robot = rhal.connect(base.url, timeout=0.2)
    await robot.open()
    await base.unplug()
    await until(lambda: not robot.connected)
    await robot.close()
    assert not robot.is_open


async def test_the_base_over_udp_multicast_on_this_computer_only():
    # An IPv6 interface-local group (ff11::...): a bus between processes that the kernel never
    # sends out of the computer, and that echoes every frame back to its sender.
    emu = Cia402BaseEmulator(interface="udp_multicast", **QUICK)
    try:
        await emu.start()
    except (OSError, can.CanError) as exc:
        pytest.skip(f"no IPv6 multicast here: {exc}")
    try:
        assert emu.url.startswith("can://udp_multicast/ff11::")
        async with rhal.connect(emu.url) as bot:
            await bot.drive(0.2, 0.0)
            left, right = wheel_targets(0.2, 0.0)
            await until(lambda: (emu.left.target, emu.right.target) == (left, right))
            await bot.stop()
            await until(lambda: emu.stops == 1)
            assert bot.errors == 0
    finally:
        await emu.stop()


# -- the drive emulator itself enforces the standard -----------------------------------------


async def test_the_drive_emulator_enforces_the_402_state_machine():
    channel = "rhal-can-enforce"
    drive = Cia402Drive(7, channel)
    await asyncio.to_thread(drive.start)
    network = canopen.Network(can.Bus(interface="virtual", channel=channel))
    network.NOTIFIER_CYCLE = 0.05
    try:
        network.connect()
        node = network.add_node(7, drive.eds)

        def write(index, value):
            node.sdo[index].raw = value

        def steps():
            write(0x60FF, 1000)
            assert drive.velocity == 0, "SWITCH ON DISABLED: no motion"
            write(0x6040, 0x0F)
            assert drive.state == "SWITCH ON DISABLED", "enable operation cannot skip steps"
            for controlword, state in [(0x06, "READY TO SWITCH ON"), (0x07, "SWITCHED ON"),
                                       (0x0F, "OPERATION ENABLED")]:  # fmt: skip
                write(0x6040, controlword)
                assert drive.state == state
            assert drive.velocity == 0, "mode 0: no motion"
            write(0x6060, 1)
            assert drive.velocity == 0, "profile position mode: no velocity"
            write(0x6060, 3)
            assert drive.velocity == 1000
            assert node.sdo[0x6041].raw & 0x6F == 0x27
            write(0x6040, 0x10F)
            assert drive.velocity == 0, "halt"
            write(0x6040, 0x0F)
            write(0x6040, 0x02)
            assert drive.state == "QUICK STOP ACTIVE" and drive.velocity == 0
            write(0x6040, 0x00)
            assert drive.state == "SWITCH ON DISABLED"
            with pytest.raises(canopen.SdoAbortedError):
                write(0x6060, 7)  # interpolated position: not supported
            drive.fault(0x3210)
            assert node.sdo[0x6041].raw & 0x4F == 0x08 and node.sdo[0x603F].raw == 0x3210
            write(0x6040, 0x06)
            assert drive.state == "FAULT", "only a fault reset leaves FAULT"
            write(0x6040, 0x80)
            assert drive.state == "SWITCH ON DISABLED" and drive.error_code == 0

        await asyncio.to_thread(steps)
    finally:
        await asyncio.to_thread(network.disconnect)
        await asyncio.to_thread(drive.unplug)


# -- cia402: noise ---------------------------------------------------------------------------

#: Frames addressed to the drives (NMT, RPDOs, SDO requests) would be obeyed by a real drive
#: too, and the drives' heartbeats state their NMT state: those are not noise.
to_the_drives = {0x000, 0x701, 0x702} | set(range(0x200, 0x580)) | set(range(0x600, 0x680))
#: What the driver hears from the two drives: COB-ID -> the only length it may have.
from_the_drives = {0x81: 8, 0x82: 8, 0x181: 3, 0x182: 3, 0x281: 8, 0x282: 8, 0x581: 8, 0x582: 8}

noise = st.lists(
    st.builds(
        lambda ident, data, extended: can.Message(
            arbitration_id=ident, data=data, is_extended_id=extended
        ),
        st.integers(0, 0x7FF).filter(lambda ident: ident not in to_the_drives)
        | st.sampled_from(sorted(from_the_drives)),
        st.binary(max_size=8),
        st.booleans(),
    )
    | st.just(can.Message(is_error_frame=True)),
    max_size=12,
)


def expected_cia402_errors(frames):
    return sum(
        1
        for frame in frames
        if frame.is_error_frame
        or (
            not frame.is_extended_id
            and frame.arbitration_id in from_the_drives
            and len(frame.data) != from_the_drives[frame.arbitration_id]
        )
    )


@pytest.fixture
async def noise_bus(base):
    bus = can.Bus(interface="virtual", channel=base.channel)
    yield bus
    bus.shutdown()


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(frames=noise)
async def test_random_frames_are_ignored_or_counted_never_a_crash(robot, base, noise_bus, frames):
    before = robot.errors
    sentinel = can.Message(arbitration_id=0x701, data=b"", is_extended_id=False)  # too short
    for frame in [*frames, sentinel]:
        noise_bus.send(frame)
    expected = expected_cia402_errors(frames) + 1
    await until(lambda: robot.errors >= before + expected)
    assert robot.errors == before + expected
    readings = await robot.sensors()
    assert readings["errors"] == robot.errors
    assert robot.connected


async def test_after_the_noise_the_base_still_drives(robot, base, noise_bus):
    before = robot.errors
    frames = [(0x181, "080003"), (0x182, "080003"), (0x281, "0000004000000000"), (0x701, "")]
    for ident, data in frames:  # FAULT, a position far away, then a sentinel heartbeat
        noise_bus.send(can.Message(arbitration_id=ident, data=bytes.fromhex(data),
                                   is_extended_id=False))  # fmt: skip
    await until(lambda: robot.errors == before + 1)  # all of it has been heard
    # The drives' own TPDOs at the next SYNC put things right.
    # Both drives: the left's TPDO may come in before the right's.
    await until(lambda: _when(robot, _both_enabled))
    await robot.drive(0.1, 0.0)
    await until(lambda: base.left.velocity != 0)


# -- dbc: commands ---------------------------------------------------------------------------


@pytest.mark.parametrize(("linear", "angular"), [(0.3, -0.5), (-0.2, 1.25), (0.0, 0.0)])
async def test_dbc_drive_encodes_the_command_message(dbc_robot, dbc_base, linear, angular):
    sent = len(dbc_base.commands)
    await dbc_robot.drive(linear, angular)
    await until(lambda: len(dbc_base.commands) > sent)
    command = dbc_base.commands[sent]
    assert (command["LinearSpeed"], command["TurnRate"]) == pytest.approx((linear, angular))
    assert command["Mode"] == 1, "other signals go at their start value (GenSigStartValue)"
    # By the DBC: int16 mm/s, int16 mrad/s, uint8 mode, little-endian.
    assert command["raw"] == struct.pack("<hhB", round(linear * 1000), round(angular * 1000), 1)
    assert dbc_base.commanded() == pytest.approx((linear, angular))


async def test_dbc_speeds_are_clamped_to_the_signal_range(dbc_base):
    async with rhal.connect(dbc_base.url, max_linear=3.0) as bot:
        await bot.drive(2.5, 0.0)  # within max_linear, beyond LinearSpeed's [-2, 2]
        await until(lambda: dbc_base.commanded() == (2.0, 0.0))


async def test_dbc_commands_repeat_while_moving_and_never_after_a_stop(dbc_robot, dbc_base):
    await dbc_robot.drive(0.2, 0.1)
    sent = len(dbc_base.commands)
    await until(lambda: len(dbc_base.commands) >= sent + 3)  # the base's timeout is 0.5 s
    assert all(c["LinearSpeed"] == 0.2 for c in dbc_base.commands[sent:])
    await dbc_robot.stop()
    await until(lambda: dbc_base.commanded() == (0.0, 0.0))
    ticks = dbc_base.feedback_sent
    await until(lambda: dbc_base.feedback_sent >= ticks + 6)  # a while of the base's own clock
    speeds = [(c["LinearSpeed"], c["TurnRate"]) for c in dbc_base.commands[sent:]]
    stop = speeds.index((0, 0))
    assert speeds[stop:] == [(0, 0)], "one zero command, and no repeat of the old speeds"


async def test_dbc_stop_sends_a_zero_command_every_call(dbc_robot, dbc_base):
    await dbc_robot.drive(0.2, 0.0)
    stops = dbc_base.stops
    for count in range(1, 4):
        await dbc_robot.stop()
        await until(lambda count=count: dbc_base.stops == stops + count)
    assert dbc_base.commanded() == (0.0, 0.0)


# -- dbc: readings ---------------------------------------------------------------------------


async def test_dbc_feedback_is_decoded_into_the_readings(dbc_robot, dbc_base):
    dbc_base.battery, dbc_base.bumper = 12.5, True
    await dbc_robot.drive(0.25, -0.4)

    def arrived(readings):
        moving = readings["velocity"] == {"linear": 0.25, "angular": -0.4}
        return moving and readings["signals"]["BaseStatus.Bumper"] == 1

    readings = await until(lambda: _when(dbc_robot, arrived))
    assert readings["battery"] == 12.5
    await dbc_robot.stop()

    def still(readings):  # stopped, and a status frame from after the stop has come
        distance = pytest.approx(dbc_base.range(), abs=0.002)
        return readings["velocity"]["linear"] == 0 and readings["range"] == distance

    readings = await until(lambda: _when(dbc_robot, still))
    assert readings["heading"] == pytest.approx(dbc_base.heading(), abs=0.02)
    assert json.loads(json.dumps(readings)) == readings
    assert set(readings) == set(dbc_robot.capabilities()["sensors"])


async def test_dbc_position_integrates_the_feedback(dbc_robot, dbc_base):
    await dbc_robot.drive(0.5, 0.0)
    readings = await until(lambda: _when(dbc_robot, lambda r: r["position"]["x"] > 0.1))
    assert readings["position"]["y"] == 0.0 and readings["position"]["theta"] == 0.0
    assert readings["heading"] == pytest.approx(90.0)  # from the base's heading signal: east


async def test_dbc_range_at_the_signal_maximum_means_nothing_in_reach():
    emu = DbcBaseEmulator(arena=20.0)  # walls 20 m away, beyond Range's 10 m
    await emu.start()
    try:
        async with rhal.connect(emu.url) as bot:
            readings = await until(lambda: _when(bot, lambda r: "BaseStatus.Range" in r["signals"]))
            assert readings["signals"]["BaseStatus.Range"] == 10.0
            assert readings["range"] is None
    finally:
        await emu.stop()


async def test_dbc_signal_units_are_converted(tmp_path):
    dbc = tmp_path / "kmh.dbc"
    dbc.write_text(
        'VERSION ""\n\nBS_:\n\nBU_: Host Base\n\n'
        "BO_ 512 Drive: 4 Host\n"
        ' SG_ Speed : 0|16@1- (0.01,0) [-20|20] "km/h" Base\n'
        ' SG_ Yaw : 16|16@1- (0.1,0) [-360|360] "deg/s" Base\n\n'
        "BO_ 513 Odometry: 4 Base\n"
        ' SG_ Speed : 0|16@1- (0.01,0) [-20|20] "km/h" Host\n'
        ' SG_ Yaw : 16|16@1- (0.1,0) [-360|360] "deg/s" Host\n'
    )
    channel = "rhal-can-units"
    peer = can.Bus(interface="virtual", channel=channel)
    feedback = can.Message(arbitration_id=513, data=struct.pack("<hh", 720, -900),
                           is_extended_id=False)  # fmt: skip
    task = peer.send_periodic(feedback, 0.05)
    url = (
        f"can://virtual/{channel}?profile=dbc&dbc={dbc}&command=Drive&speed=Drive.Speed"
        "&turn=Drive.Yaw&feedback_speed=Odometry.Speed&feedback_turn=Odometry.Yaw"
    )
    try:
        async with rhal.connect(url) as bot:
            readings = await bot.sensors()
            assert readings["velocity"] == pytest.approx(
                {"linear": 7.2 / 3.6, "angular": math.radians(-90.0)}
            )
            await bot.drive(0.5, math.radians(30.0))
            frame = await asyncio.to_thread(_next_frame, peer, 512)
            assert struct.unpack("<hh", frame.data) == (180, 300)  # 1.8 km/h, 30.0 deg/s
    finally:
        task.stop()
        peer.shutdown()


# -- dbc: faults -----------------------------------------------------------------------------


async def test_dbc_open_fails_clearly_without_feedback():
    bot = rhal.connect("can://virtual/rhal-can-silent?profile=dbc", timeout=0.05)
    with pytest.raises(RobotConnectionError, match="no BaseFeedback frame from the base"):
        await bot.open()


async def test_dbc_frames_that_do_not_decode_are_counted(dbc_robot, dbc_base):
    before = dbc_robot.errors
    dbc_base.inject(can.Message(arbitration_id=0x101, data=b"\x01", is_extended_id=False))
    dbc_base.inject(can.Message(arbitration_id=0x555, data=b"\x01", is_extended_id=False))
    dbc_base.inject(can.Message(arbitration_id=0x101, data=bytes(6), is_extended_id=True))
    dbc_base.inject(can.Message(is_error_frame=True))
    await until(lambda: dbc_robot.errors == before + 2)  # the short one and the error frame
    await dbc_robot.drive(0.1, 0.0)
    await until(lambda: dbc_base.commanded() == (0.1, 0.0))


async def test_dbc_feedback_loss_is_a_clear_error_until_it_returns(dbc_base):
    dbc_robot = rhal.connect(dbc_base.url, timeout=0.3)
    await dbc_robot.open()
    await dbc_robot.drive(0.2, 0.0)
    await dbc_base.unplug()
    error = await until(lambda: failing(dbc_robot.sensors))
    assert "(no BaseFeedback frame from the base for 0.3 s); reconnecting" in str(error)
    with pytest.raises(RobotConnectionError, match="no link"):
        await dbc_robot.drive(0.2, 0.0)
    sent = len(dbc_base.commands)
    await dbc_base.replug()
    await until(lambda: dbc_robot.connected)
    assert all(c["LinearSpeed"] == 0 for c in dbc_base.commands[sent:]), "no old speed again"
    await dbc_robot.drive(-0.1, 0.0)
    await until(lambda: dbc_base.commanded() == (-0.1, 0.0))
    await dbc_robot.close()


dbc_noise = st.lists(
    st.builds(
        lambda ident, data, extended: can.Message(
            arbitration_id=ident, data=data, is_extended_id=extended
        ),
        st.integers(0, 0x7FF).filter(lambda ident: ident != 0x100)
        | st.sampled_from([0x101, 0x102]),
        st.binary(max_size=8),
        st.booleans(),
    ),
    max_size=12,
)
#: What the driver decodes, by the example DBC: id -> the message's length in bytes.
dbc_lengths = {0x101: 6, 0x102: 5}


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(frames=dbc_noise)
async def test_dbc_random_frames_are_ignored_or_counted(dbc_robot, dbc_base, frames):
    before = dbc_robot.errors
    sentinel = can.Message(arbitration_id=0x102, data=b"\x00", is_extended_id=False)
    for frame in [*frames, sentinel]:
        dbc_base.inject(frame)
    expected = 1 + sum(
        1
        for frame in frames
        if not frame.is_extended_id
        and frame.arbitration_id in dbc_lengths
        and len(frame.data) < dbc_lengths[frame.arbitration_id]
    )
    await until(lambda: dbc_robot.errors >= before + expected)
    assert dbc_robot.errors == before + expected
    readings = await dbc_robot.sensors()
    assert json.loads(json.dumps(readings)) == readings


# -- the emulators' shared interface ---------------------------------------------------------


@pytest.mark.parametrize("make", [lambda: Cia402BaseEmulator(**QUICK), DbcBaseEmulator])
async def test_a_program_drives_turns_and_stops_on_either_base(make):
    emu = make()
    await emu.start()
    try:
        async with rhal.connect(emu.url, timeout=0.3) as bot:
            await bot.drive(0.2, 0.0)
            await until(lambda: emu.commanded() == pytest.approx((0.2, 0.0), abs=1e-3))
            start = await bot.sensors()
            await until(lambda: _when(bot, lambda r: r["position"]["x"] > 0.02))
            await bot.drive(0.0, 1.0)
            await until(lambda: _when(bot, lambda r: r["heading"] < start["heading"] - 5))
            stops = emu.stops
            await bot.stop()
            await until(lambda: emu.stops == stops + 1)
            assert emu.commanded() == (0.0, 0.0)
            readings = await bot.sensors()
            assert 0.0 <= readings["heading"] < 360.0
            await emu.unplug()
            await until(lambda: failing(bot.sensors))
            await emu.replug()
            await until(lambda: bot.connected)
            await bot.drive(0.1, 0.0)
            await until(lambda: emu.commanded() == pytest.approx((0.1, 0.0), abs=1e-3))
    finally:
        await emu.stop()


def _next_frame(bus, ident, timeout=DEADLINE):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        frame = bus.recv(0.1)
        if frame is not None and frame.arbitration_id == ident:
            return frame
    raise AssertionError(f"no frame 0x{ident:X}")


def _both_enabled(readings) -> bool:
    drives = readings["drives"]
    return all(drives[side]["state"] == "OPERATION ENABLED" for side in ("left", "right"))


async def _when(bot, condition):
    readings = await bot.sensors()
    return readings if condition(readings) else None
