"""Frames for the gateway tests, made with pymavlink (a separate implementation from ours)."""

from pymavlink.dialects.v10 import ardupilotmega as v1
from pymavlink.dialects.v20 import ardupilotmega as v2


def mav(sysid=1, compid=1, version=2):
    dialect = v2 if version == 2 else v1
    return dialect.MAVLink(None, srcSystem=sysid, srcComponent=compid)


def heartbeat(sysid=1, compid=1, version=2) -> bytes:
    m = mav(sysid, compid, version)
    return bytes(m.heartbeat_encode(2, 3, 0, 0, 4).pack(m))


def command(sysid, compid, tsys, tcomp, version=2, param=1.0) -> bytes:
    m = mav(sysid, compid, version)
    return bytes(m.command_long_encode(tsys, tcomp, 31010, 0, param, 0, 0, 0, 0, 0, 0).pack(m))


def attitude(sysid=1, compid=1, t=0) -> bytes:
    m = mav(sysid, compid)
    return bytes(m.attitude_encode(t, 0.1, 0.2, 0.3, 0, 0, 0).pack(m))


def signed_heartbeat(sysid=1, compid=1) -> bytes:
    m = mav(sysid, compid)
    m.signing.secret_key = bytes(range(32))
    m.signing.link_id = 3
    m.signing.timestamp = 123456
    m.signing.sign_outgoing = True
    return bytes(m.heartbeat_encode(2, 3, 0, 0, 4).pack(m))
