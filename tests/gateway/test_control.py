"""What counts as commanding a vehicle (gateway.control), on frames pymavlink itself makes,
MAVLink 1 and 2; and the COMMAND_ACK a refused command gets, read back by pymavlink."""

import pytest
from pymavlink.dialects.v10 import ardupilotmega as v1
from pymavlink.dialects.v20 import ardupilotmega as v2

from gateway.control import command_of, commands_vehicle, denied_ack
from gateway.framing import Framer

COMMANDS = {
    "arm": lambda m: m.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
    "set mode (command)": lambda m: m.command_long_encode(1, 1, 176, 0, 1, 15, 0, 0, 0, 0, 0),
    "reposition (COMMAND_INT)": lambda m: m.command_int_encode(1, 1, 6, 192, 0, 0, 0, 0, 0, 0,
                                                               475, 85, 10),
    "set mode": lambda m: m.set_mode_encode(1, 1, 15),
    "velocity setpoint": lambda m: m.set_position_target_local_ned_encode(
        0, 1, 1, 8, 0b110111000111, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0, 0),
    "global setpoint": lambda m: m.set_position_target_global_int_encode(
        0, 1, 1, 6, 0b110111111000, 475000000, 85000000, 10, 0, 0, 0, 0, 0, 0, 0, 0),
    "attitude": lambda m: m.set_attitude_target_encode(0, 1, 1, 0, [1, 0, 0, 0], 0, 0, 0, 0.5),
    "manual control": lambda m: m.manual_control_encode(1, 500, 0, 500, 0, 0),
    "rc override": lambda m: m.rc_channels_override_encode(1, 1, *[1500] * 8),
    "param write": lambda m: m.param_set_encode(1, 1, b"CRUISE_SPEED", 9.0, 9),
    "mission upload": lambda m: m.mission_count_encode(1, 1, 3),
    "mission clear": lambda m: m.mission_clear_all_encode(1, 1),
    "mission item": lambda m: m.mission_item_int_encode(1, 1, 0, 6, 16, 0, 1, 0, 0, 0, 0,
                                                        475, 85, 10),
}  # fmt: skip
READS = {
    "heartbeat": lambda m: m.heartbeat_encode(6, 8, 0, 0, 0),
    "param read": lambda m: m.param_request_read_encode(1, 1, b"CRUISE_SPEED", -1),
    "param list": lambda m: m.param_request_list_encode(1, 1),
    "mission list": lambda m: m.mission_request_list_encode(1, 1),
    "data stream": lambda m: m.request_data_stream_encode(1, 1, 0, 4, 1),
    "message interval": lambda m: m.command_long_encode(1, 1, 511, 0, 33, 200000, 0, 0, 0, 0, 0),
    "request message": lambda m: m.command_long_encode(1, 1, 512, 0, 242, 0, 0, 0, 0, 0, 0),
    "timesync": lambda m: m.timesync_encode(0, 123),
}  # fmt: skip


def framed(dialect, make):
    mav = dialect.MAVLink(None, srcSystem=200, srcComponent=190)
    data = make(mav).pack(mav)
    frames = Framer().feed(data)
    assert len(frames) == 1
    return frames[0]


@pytest.mark.parametrize("dialect", [v1, v2], ids=["mavlink1", "mavlink2"])
@pytest.mark.parametrize("name", list(COMMANDS) + list(READS))
def test_commands_and_reads(dialect, name):
    make = COMMANDS.get(name) or READS[name]
    try:
        frame, sysid, compid, msgid, tsys, tcomp = framed(dialect, make)
    except (AttributeError, TypeError) as exc:  # not in MAVLink 1 (COMMAND_INT's extensions...)
        pytest.fail(f"{name} cannot be made in {dialect.__name__}: {exc}")
    assert commands_vehicle(frame, msgid) is (name in COMMANDS), name


def test_a_command_with_its_id_trimmed_off_is_a_command():
    """MAVLink 2 trims trailing zero bytes: a COMMAND_LONG whose command id is 0 (and so
    trimmed) is still a command (MAV_CMD 0 is no read)."""
    frame, *_, msgid, _, _ = framed(v2, lambda m: m.command_long_encode(0, 0, 0, 0, 0, 0, 0, 0,
                                                                        0, 0, 0))  # fmt: skip
    assert command_of(frame) == 0 and commands_vehicle(frame, msgid)


def test_a_refused_command_is_answered_denied_to_its_sender():
    frame, sysid, compid, msgid, tsys, tcomp = framed(v2, COMMANDS["arm"])
    ack = denied_ack(frame, msgid, (sysid, compid), (tsys, tcomp))
    decoded = v2.MAVLink(None).decode(bytearray(ack))
    assert decoded.get_type() == "COMMAND_ACK"
    assert (decoded.command, decoded.result) == (400, v2.MAV_RESULT_DENIED)
    assert (decoded.target_system, decoded.target_component) == (200, 190)
    assert (decoded.get_srcSystem(), decoded.get_srcComponent()) == (1, 1)
    setpoint = framed(v2, COMMANDS["velocity setpoint"])
    assert denied_ack(setpoint[0], setpoint[3], (200, 190), (1, 1)) is None  # nothing waits
