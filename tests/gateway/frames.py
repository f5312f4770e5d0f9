"""Frames for the gateway tests, made with pymavlink (a separate implementation from ours)."""

import asyncio

from pymavlink.dialects.v10 import ardupilotmega as v1
from pymavlink.dialects.v20 import ardupilotmega as v2

from gateway.framing import Framer


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


class Sink(asyncio.DatagramProtocol):
    """A UDP listener that keeps the frames it receives, each with the loop time it came."""

    def __init__(self):
        self.framer = Framer()
        self.frames, self.times = [], []

    def datagram_received(self, data, addr):
        now = asyncio.get_running_loop().time()
        for frame in self.framer.feed(data):
            self.frames.append(frame[0])
            self.times.append(now)


async def sink():
    """(transport, Sink, "127.0.0.1:PORT") listening on a free loopback port."""
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_datagram_endpoint(Sink, local_addr=("127.0.0.1", 0))
    return transport, protocol, f"127.0.0.1:{transport.get_extra_info('sockname')[1]}"
