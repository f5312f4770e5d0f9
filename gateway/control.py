"""Which MAVLink frames command a vehicle, and which only read it (no Django here).

A program's or a ground station's frames pass a guard that asks whether they may command the
vehicle now (robots/gateway.py: the control lease, an endpoint's ``control`` setting).
Telemetry and read requests always pass: heartbeats, parameter and mission reads, message
rates, time sync, pings, and the COMMAND_LONG/INT commands that only ask for messages. Every
other frame is a command, whatever it is: arming, modes, setpoints, manual control, RC
overrides, mission and parameter writes, DO commands, file transfer... A new message id is a
command until it is listed here as a read.

    commands_vehicle(frame, msgid)   # True: only with control
    denied_ack(frame, msgid, sender, target)  # the COMMAND_ACK (DENIED) a refused command
                                              # gets back, as from the system it addressed
"""

import struct

from pymavlink.dialects.v20 import ardupilotmega as mavlink

COMMAND_INT, COMMAND_LONG = 75, 76
COMMAND_AT = 28  # both: seven 4-byte fields, then the uint16 command (v2 may trim it off)

# Frames that read, or keep a link alive: never a command.
READS = frozenset({
    0,    # HEARTBEAT
    2,    # SYSTEM_TIME
    4,    # PING
    20,   # PARAM_REQUEST_READ
    21,   # PARAM_REQUEST_LIST
    40,   # MISSION_REQUEST
    42,   # MISSION_CURRENT
    43,   # MISSION_REQUEST_LIST
    47,   # MISSION_ACK (to the vehicle's own transfer)
    51,   # MISSION_REQUEST_INT
    66,   # REQUEST_DATA_STREAM
    111,  # TIMESYNC
    117,  # LOG_REQUEST_LIST
    119,  # LOG_REQUEST_DATA
    122,  # LOG_REQUEST_END
    300,  # PROTOCOL_VERSION
    320,  # PARAM_EXT_REQUEST_READ
    321,  # PARAM_EXT_REQUEST_LIST
})  # fmt: skip
# COMMAND_LONG/INT commands that only ask for something.
READ_COMMANDS = frozenset({
    410,  # MAV_CMD_GET_HOME_POSITION
    511,  # MAV_CMD_SET_MESSAGE_INTERVAL (how often telemetry comes)
    512,  # MAV_CMD_REQUEST_MESSAGE
    519,  # MAV_CMD_REQUEST_PROTOCOL_VERSION
    520,  # MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
    521,  # MAV_CMD_REQUEST_CAMERA_INFORMATION
    522,  # MAV_CMD_REQUEST_CAMERA_SETTINGS
    525,  # MAV_CMD_REQUEST_STORAGE_INFORMATION
    527,  # MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS
    528,  # MAV_CMD_REQUEST_FLIGHT_INFORMATION
})  # fmt: skip


def payload(frame: bytes) -> bytes:
    """A frame's payload, as sent (MAVLink 2 trims trailing zero bytes)."""
    start = 10 if frame[0] == 0xFD else 6
    return frame[start : start + frame[1]]


def command_of(frame: bytes) -> int:
    """The command id of a COMMAND_LONG or COMMAND_INT frame (0 if trimmed away)."""
    body = payload(frame)[COMMAND_AT : COMMAND_AT + 2].ljust(2, b"\0")
    return struct.unpack("<H", body)[0]


def commands_vehicle(frame: bytes, msgid: int) -> bool:
    if msgid in (COMMAND_LONG, COMMAND_INT):
        return command_of(frame) not in READ_COMMANDS
    return msgid not in READS


def denied_ack(
    frame: bytes, msgid: int, sender: tuple[int, int], target: tuple[int, int]
) -> bytes | None:
    """For a refused COMMAND_LONG/INT: the COMMAND_ACK (MAV_RESULT_DENIED) its `sender` waits
    for, as from the `target` it addressed; None for other frames (nothing waits)."""
    if msgid not in (COMMAND_LONG, COMMAND_INT):
        return None
    mav = mavlink.MAVLink(None, srcSystem=target[0] or 1, srcComponent=target[1] or 1)
    ack = mav.command_ack_encode(
        command_of(frame), mavlink.MAV_RESULT_DENIED, 0, 0, sender[0], sender[1]
    )
    return ack.pack(mav)
