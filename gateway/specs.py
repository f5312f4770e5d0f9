"""Endpoints described as data: what the API, the database and the admin store.

    {"type": "udp" | "tcp", "mode": "server" | "client", "address": "host:port"}
    {"type": "serial", "device": "/dev/ttyACM0", "baud": 57600}

with optional ``read_only``, ``allow`` and ``block`` (lists of MAVLink message ids), and
``control``: whether what it sends may command the vehicle — ``always`` (a pilot's ground
station must be able to take over), ``lease`` (only while no program holds the robot, and
never after an emergency stop) or ``never`` (telemetry and reads only; gateway.control).
``check`` says what is wrong in words a user can act on; ``build`` makes the router's endpoint.
"""

from __future__ import annotations

from gateway.router import (
    Endpoint,
    SerialEndpoint,
    TcpClientEndpoint,
    TcpServerEndpoint,
    UdpEndpoint,
    split_address,
)

TYPES = ("udp", "tcp", "serial")
MODES = ("server", "client")
CONTROLS = ("always", "lease", "never")
BAUDS = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600,
         1000000, 1500000, 2000000, 3000000)  # fmt: skip
MAX_MSGID = (1 << 24) - 1  # MAVLink 2 message ids are 24 bits


def check(spec: dict) -> dict:
    """The spec, normalised (only its own keys, defaults filled in); ValueError if unusable."""
    kind = spec.get("type")
    if kind not in TYPES:
        raise ValueError(f"type must be one of {', '.join(TYPES)}, not {kind!r}")
    clean: dict = {"type": kind}
    if kind == "serial":
        device = spec.get("device")
        if not isinstance(device, str) or not device.startswith("/"):
            raise ValueError(f"device must be a path such as /dev/ttyACM0, not {device!r}")
        baud = spec.get("baud", 57600)
        if isinstance(baud, bool) or baud not in BAUDS:
            raise ValueError(f"baud must be a serial speed ({', '.join(map(str, BAUDS))})")
        clean.update(device=device, baud=baud)
    else:
        mode = spec.get("mode", "client")
        if mode not in MODES:
            raise ValueError(f"mode must be server or client, not {mode!r}")
        address = spec.get("address")
        if not isinstance(address, str):
            raise ValueError("address must be HOST:PORT, e.g. 0.0.0.0:14550")
        _, port = split_address(address)
        if port == 0 and mode == "client":
            raise ValueError(f"a client needs the port to send to: {address!r}")
        clean.update(mode=mode, address=address)
    clean["read_only"] = _flag(spec.get("read_only", False))
    control = spec.get("control", "always")
    if control not in CONTROLS:
        raise ValueError(f"control must be one of {', '.join(CONTROLS)}, not {control!r}")
    clean["control"] = control
    allow = spec.get("allow")
    clean["allow"] = None if allow is None else _message_ids("allow", allow)
    clean["block"] = _message_ids("block", spec.get("block") or [])
    return clean


def build(spec: dict, name: str = "") -> Endpoint:
    spec = check(spec)
    common = {
        "name": name,
        "read_only": spec["read_only"],
        "allow": None if spec["allow"] is None else frozenset(spec["allow"]),
        "block": frozenset(spec["block"]),
    }
    if spec["type"] == "serial":
        return SerialEndpoint(device=spec["device"], baud=spec["baud"], **common)
    if spec["type"] == "udp":
        return UdpEndpoint(address=spec["address"], mode=spec["mode"], **common)
    if spec["mode"] == "server":
        return TcpServerEndpoint(address=spec["address"], **common)
    return TcpClientEndpoint(address=spec["address"], **common)


def describe(spec: dict) -> str:
    """``udpin:0.0.0.0:14550``, ``tcp:10.0.0.5:5760``, ``/dev/ttyACM0:57600``: the route
    command's words for it."""
    if spec["type"] == "serial":
        return f"{spec['device']}:{spec['baud']}"
    suffix = "in" if spec["mode"] == "server" else ""
    return f"{spec['type']}{suffix}:{spec['address']}"


def _flag(value) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"read_only must be true or false, not {value!r}")
    return value


def _message_ids(name: str, ids) -> list[int]:
    if not isinstance(ids, list) or not all(
        isinstance(i, int) and not isinstance(i, bool) and 0 <= i <= MAX_MSGID for i in ids
    ):
        raise ValueError(f"{name} must be a list of MAVLink message ids (0 to {MAX_MSGID})")
    return sorted(set(ids))
