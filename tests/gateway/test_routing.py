"""The routing rules, with in-memory endpoints: three links, several systems."""

import time
from dataclasses import dataclass, field

import pytest

from gateway.router import Endpoint, Router, Stats
from tests.gateway.frames import attitude, command, heartbeat


@dataclass(eq=False)
class Memory(Endpoint):
    sent: list = field(default_factory=list)
    slow: int = 0  # pretend this many bytes wait unsent

    async def start(self):
        pass

    async def stop(self):
        pass

    def backlog(self):
        return self.slow

    def send(self, frames):
        self.sent.extend(frames)


async def three(**options):
    router = Router()
    vehicle = await router.add(Memory(name="vehicle", **options.get("vehicle", {})))
    gcs = await router.add(Memory(name="gcs", **options.get("gcs", {})))
    program = await router.add(Memory(name="program", **options.get("program", {})))
    # Each side introduces itself: vehicle 1 (autopilot 1, camera 100), a second vehicle 2
    # behind the same link, the GCS 255/190, a program 254/1.
    vehicle.received(heartbeat(1, 1) + heartbeat(1, 100) + heartbeat(2, 1))
    gcs.received(heartbeat(255, 190))
    program.received(heartbeat(254, 1))
    for e in (vehicle, gcs, program):
        e.sent.clear()
        e.stats = Stats()
    return router, vehicle, gcs, program


async def test_broadcasts_go_everywhere_but_back():
    router, vehicle, gcs, program = await three()
    vehicle.received(attitude(1, 1))
    assert gcs.sent == [attitude(1, 1)] and program.sent == [attitude(1, 1)]
    assert vehicle.sent == []


async def test_targeted_frames_go_only_where_the_target_was_seen():
    router, vehicle, gcs, program = await three()
    gcs.received(command(255, 190, 1, 100))
    assert vehicle.sent == [command(255, 190, 1, 100)] and program.sent == []
    vehicle.received(command(1, 1, 254, 1))  # to the program alone
    assert program.sent == [command(1, 1, 254, 1)] and gcs.sent == []


async def test_a_system_target_reaches_any_component_of_it():
    router, vehicle, gcs, program = await three()
    program.received(command(254, 1, 2, 0))
    assert vehicle.sent == [command(254, 1, 2, 0)] and gcs.sent == []


async def test_an_unseen_target_goes_nowhere_and_system_zero_is_broadcast():
    router, vehicle, gcs, program = await three()
    gcs.received(command(255, 190, 9, 1))
    assert vehicle.sent == [] and program.sent == []
    gcs.received(command(255, 190, 0, 0))
    assert vehicle.sent == [command(255, 190, 0, 0)] == program.sent


async def test_block_and_allow_filter_both_ways():
    router, vehicle, gcs, program = await three(gcs={"block": frozenset({30})},
                                                program={"allow": frozenset({0, 76})})  # fmt: skip
    vehicle.received(attitude(1, 1) + heartbeat(1, 1))
    assert gcs.sent == [heartbeat(1, 1)] and program.sent == [heartbeat(1, 1)]
    program.received(attitude(254, 1))
    assert vehicle.sent == [] and program.stats.drops == 1


async def test_a_read_only_endpoint_watches_but_is_not_heard():
    router, vehicle, gcs, program = await three(gcs={"read_only": True})
    gcs.received(command(255, 190, 1, 1) + heartbeat(255, 190))
    assert vehicle.sent == [] and program.sent == []
    assert gcs.stats.drops == 2
    vehicle.received(attitude(1, 1))
    assert gcs.sent == [attitude(1, 1)]


async def test_a_slow_endpoint_drops_and_counts_without_holding_the_others():
    router, vehicle, gcs, program = await three(gcs={"queue_limit": 1000})
    gcs.slow = 5000
    vehicle.received(attitude(1, 1) * 3)
    assert gcs.sent == [] and gcs.stats.drops == 3
    assert len(program.sent) == 3


async def test_stats_count_frames_bytes_and_systems():
    router, vehicle, gcs, program = await three()
    vehicle.received(attitude(1, 1) + b"\x00junk")
    row = next(r for r in router.stats() if r["name"] == "vehicle")
    assert row["stats"]["frames_in"] == 1
    assert row["stats"]["parse_errors"] == 0
    assert [(s["system"], s["component"]) for s in row["systems"]] == [(1, 1), (1, 100), (2, 1)]
    assert next(r for r in router.stats() if r["name"] == "gcs")["stats"]["frames_out"] == 1


@pytest.mark.parametrize("spec,kind,mode", [
    ("udp:127.0.0.1:1", "UdpEndpoint", "client"), ("udpin:0.0.0.0:14550", "UdpEndpoint", "server"),
    ("tcp:h:5760", "TcpClientEndpoint", None), ("tcpin:127.0.0.1:5760", "TcpServerEndpoint", None),
    ("/dev/ttyACM0:921600", "SerialEndpoint", None), ("/dev/ttyUSB0", "SerialEndpoint", None),
])  # fmt: skip
def test_endpoint_specs(spec, kind, mode):
    from gateway.router import endpoint_from_spec

    endpoint = endpoint_from_spec(spec)
    assert type(endpoint).__name__ == kind
    assert mode is None or endpoint.mode == mode


async def test_rates_per_second_and_silent_systems_forgotten(monkeypatch):
    router, vehicle, gcs, program = await three()
    clock = [time.monotonic()]
    monkeypatch.setattr("gateway.router.time.monotonic", lambda: clock[0])
    router.tick()
    for t in range(50):
        vehicle.received(attitude(1, 1, t))
    clock[0] += 2.0
    router.tick()
    rates = next(r for r in router.stats() if r["name"] == "vehicle")["rates"]
    assert rates["frames_in"] == 25.0
    assert next(r for r in router.stats() if r["name"] == "gcs")["rates"]["frames_out"] == 25.0
    program.received(heartbeat(7, 1))
    clock[0] += 31.0
    program.received(heartbeat(8, 1))
    router.tick()  # 7 silent for 31 s: forgotten, a command to it is broadcast no more there
    assert [s["system"] for s in program.as_dict()["systems"]] == [8]
    assert not program.sees(7, 0) and program.sees(8, 1)
