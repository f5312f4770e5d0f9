"""The ARCOS robot emulator itself, read back from its bytes by code written here.

Nothing here uses the driver (``rhal.arcos``, ``rhal.pioneer``): packets are framed, checked
and decoded below, and the expected numbers come from the model table and ARIA's formulas.
"""

import asyncio
import math
import os
import struct
from dataclasses import dataclass

import pytest

from tests.rhal.arcos_emulator import ArcosEmulator, arcos_packet
from tests.rhal.arcos_models import MODELS

# -- the wire, written again for the test ----------------------------------------------------


def checksum(body: bytes) -> int:
    """Sum of big-endian byte pairs, an odd last byte XORed in."""
    total = 0
    for i in range(0, len(body) - 1, 2):
        total = (total + (body[i] << 8 | body[i + 1])) & 0xFFFF
    return total ^ body[-1] if len(body) % 2 else total


def command(number: int, arg: int | None = None) -> bytes:
    body = bytes([number])
    if arg is not None:
        body += bytes([0x3B if arg >= 0 else 0x1B]) + abs(arg).to_bytes(2, "little")
    return b"\xfa\xfb" + bytes([len(body) + 2]) + body + checksum(body).to_bytes(2, "big")


def unframe(stream: bytes) -> list[bytes]:
    """Every packet body in the stream, each checked; the stream must hold nothing else."""
    bodies = []
    while stream:
        assert stream[:2] == b"\xfa\xfb", stream[:2]
        count = stream[2]
        body, check = stream[3 : 1 + count], stream[1 + count : 3 + count]
        assert int.from_bytes(check, "big") == checksum(body)
        bodies.append(body)
        stream = stream[3 + count :]
    return bodies


@dataclass
class Sip:
    kind: int
    xpos: int
    ypos: int
    thpos: int
    left: int
    right: int
    stall_bumpers: int
    flags: int
    sonar: dict[int, int]

    # ARIA's ArBumpers: the front ring in the high byte, the rear in the low, above each stall bit.
    @property
    def front_bumpers(self) -> int:
        return self.stall_bumpers >> 9 & 0x7F

    @property
    def rear_bumpers(self) -> int:
        return self.stall_bumpers >> 1 & 0x7F


def decode_sip(body: bytes) -> Sip:
    kind, x, y, th, left, right, _battery, stall, _control, flags, _compass, count = (
        struct.unpack_from("<BHHhhhBHhHBB", body)
    )
    offset = struct.calcsize("<BHHhhhBHhHBB")
    sonar = {}
    for _ in range(count):
        number, reading = struct.unpack_from("<BH", body, offset)
        sonar[number] = reading
        offset += 3
    assert len(body) - offset == 8  # GRIPSTATE ANPORT ANALOG DIGIN DIGOUT BATTERYX10 CHARGE
    return Sip(kind, x, y, th, left, right, stall, flags, sonar)


def next_sip(emu: ArcosEmulator) -> Sip:
    (body,) = unframe(arcos_packet(emu.sip()))
    assert body[0] in (0x32, 0x33)
    return decode_sip(body)


def opened(model: str, **options) -> ArcosEmulator:
    """An emulator taken through SYNC0-2, OPEN and ENABLE 1 by bytes fed in."""
    emu = ArcosEmulator(model, **options)
    for packet in (command(0), command(1), command(2), command(1), command(4, 1)):
        emu.feed(packet)
    assert emu.state == "open" and emu.motors and emu.bad_packets == 0
    return emu


# -- the table -------------------------------------------------------------------------------

LISTED = (
    "p2at p2at8 p2at8+ p2ce p2d8 p2d8+ p2de p2df p2dx p2it p2pb p2pp p3at p3at-sh p3atiw-sh "
    "p3dx p3dx-sh peoplebot-sh powerbot powerbot-sh amigo amigo-sh patrolbot-sh pioneer-lx "
    "seekur seekurjr mt400 pion1m pion1x pionat psos1m psos1x psos43m perfpb perfpb+ "
    "researchPB wheelchair-sh"
).split()


def test_the_table_has_every_listed_model_whole():
    assert set(LISTED) <= set(MODELS)
    for name, model in MODELS.items():
        assert model.subclass == name
        assert model.source == f"reedhedges/AriaCoda: params/{name}.p"
        assert model.robot_class in ("Pioneer", "MTX")
        assert len(model.sonar_poses) == model.sonar_count
        assert all(0 < factor for factor in (model.dist_conv, model.vel_conv, model.range_conv))
        assert model.diff_conv > 0 and model.max_vel > 0 and model.max_rvel > 0
        assert 0 <= model.front_bumpers <= 7 and 0 <= model.rear_bumpers <= 7
        # AngleConvFactor is the firmware's angle step, printed with five decimals.
        step = math.tau / model.angle_units_per_turn
        assert model.angle_conv == pytest.approx(step, abs=5e-6)


@pytest.mark.parametrize(
    ("name", "dist", "vel", "rng", "diff", "top"),
    [("p3at", 0.465, 1.0, 1.0, 0.0034, (1200, 300)),
     ("p3dx-sh", 1.0, 1.0, 1.0, 0.0056, (2200, 500)),
     ("p2at", 1.32, 1.0, 0.268, 0.0034, (1200, 300)),
     ("amigo", 0.5083, 0.6154, 1.0, 0.011, (1000, 300)),
     ("pion1m", 0.05066, 2.5332, 0.1734, 0.00333, (400, 100)),
     ("powerbot", 0.5813, 1.0, 1.0, 0.00373, (2000, 360))],
)  # fmt: skip
def test_table_values_as_in_the_parameter_files(name, dist, vel, rng, diff, top):
    model = MODELS[name]
    assert (model.dist_conv, model.vel_conv, model.range_conv, model.diff_conv) == (
        dist, vel, rng, diff,
    )  # fmt: skip
    assert (model.max_vel, model.max_rvel) == top


def test_table_oddities_kept():
    assert MODELS["pioneer-lx"].robot_class == "MTX"
    assert MODELS["powerbot"].sonar_count == 32 and MODELS["powerbot"].sonar_poses[31] is None
    assert MODELS["powerbot-sh"].sonar_poses[31] == (0, 0, -180)
    assert MODELS["powerbot-sh-uarcs"].sonar_count == 16
    assert (MODELS["seekur"].front_bumpers, MODELS["seekur"].rear_bumpers) == (5, 3)
    assert MODELS["seekur"].sonar_count == 0
    assert (MODELS["p3at"].front_bumpers, MODELS["p3at"].optional_front_bumpers) == (0, 5)
    assert MODELS["pion1m"].angle_units_per_turn == 1024


# -- motion ----------------------------------------------------------------------------------


def test_p3at_vel_500_for_2_s_reports_robot_units():
    emu = opened("p3at")
    emu.feed(command(11, 500))
    emu.step(2.0)
    assert emu.true_pose() == pytest.approx((1.0, 0.0, 0.0), abs=1e-9)
    sip = next_sip(emu)
    assert sip.kind == 0x33  # moving
    assert sip.xpos == round(1000 / 0.465) == 2151  # not 1000: the P3-AT counts 0.465 mm
    assert sip.xpos * 0.465 == pytest.approx(1000, abs=0.465)
    assert (sip.ypos, sip.thpos) == (0, 0)
    assert (sip.left, sip.right) == (500, 500)  # VelConvFactor 1


def test_p3dx_sh_counts_millimetres():
    emu = opened("p3dx-sh")
    emu.feed(command(11, 500))
    emu.step(2.0)
    assert next_sip(emu).xpos == 1000


def test_p3at_rotation_reports_angle_steps_and_wheel_speeds():
    emu = opened("p3at")
    emu.feed(command(21, 45))  # deg/s
    emu.step(2.0)
    assert emu.true_pose() == pytest.approx((0.0, 0.0, math.pi / 2), abs=1e-9)
    sip = next_sip(emu)
    assert sip.thpos == 1024  # a quarter of 4096 steps a turn
    assert sip.thpos * MODELS["p3at"].angle_conv == pytest.approx(math.pi / 2, rel=3e-3)
    # ARIA: omega = (right - left) / 2 * DiffConvFactor, in rad/s.
    assert sip.right == -sip.left == round(math.radians(45) / 0.0034) == 231
    omega = (sip.right - sip.left) / 2 * 0.0034
    assert math.degrees(omega) == pytest.approx(45, abs=0.2)


def test_arc_and_negative_directions():
    emu = opened("p3at")
    emu.feed(command(11, -200))
    emu.feed(command(21, -30))
    emu.step(3.0)
    x, y, th = emu.true_pose()
    assert th == pytest.approx(-math.pi / 2)
    radius = 0.2 / math.radians(30)  # m; backing while turning clockwise swings to the left
    assert (x, y) == pytest.approx((-radius, radius), abs=1e-3)
    sip = next_sip(emu)
    assert sip.xpos == round(x * 1000 / 0.465) & 0x7FFF
    assert sip.ypos == round(y * 1000 / 0.465) & 0x7FFF
    assert sip.thpos == -1024
    spin = math.radians(-30) / 0.0034
    assert (sip.left, sip.right) == (round(-200 - spin), round(-200 + spin))


@pytest.mark.parametrize(
    ("name", "vel", "rvel", "kept"),
    [("p3at", 2000, 400, (1200, 300)),
     ("p3at", -2000, -400, (-1200, -300)),
     ("pion1m", 1000, 500, (400, 100)),
     ("seekurjr", 1500, 90, (1200, 80)),
     ("p3dx-sh", 2000, 400, (2000, 400))],
)  # fmt: skip
def test_speeds_above_the_models_maximum_are_clamped(name, vel, rvel, kept):
    emu = opened(name)
    emu.feed(command(11, vel))
    emu.feed(command(21, rvel))
    assert [c.arg for c in emu.commands[-2:]] == [vel, rvel]  # recorded as sent
    assert (emu.vel, emu.rvel) == kept


def test_clamped_speed_is_the_speed_driven():
    emu = opened("p3at")
    emu.feed(command(11, 3000))
    emu.step(1.0)
    assert emu.true_pose()[0] == pytest.approx(1.2)
    assert next_sip(emu).left == 1200


def test_no_motion_without_motors():
    emu = opened("p3at")
    emu.feed(command(4, 0))
    emu.feed(command(11, 500))
    emu.step(1.0)
    assert emu.true_pose() == (0.0, 0.0, 0.0)
    assert next_sip(emu).kind == 0x32


def test_position_wraps_in_15_bits():
    emu = opened("p3at")
    for x_mm in (15000.0, 20000.0, -3000.0):
        emu.x = x_mm
        assert next_sip(emu).xpos == round(x_mm / 0.465) % 0x8000


def test_pioneer_1_units():
    emu = opened("pion1m")
    emu.feed(command(11, 300))
    emu.step(1.0)
    sip = next_sip(emu)
    assert sip.xpos == round(300 / 0.05066)
    assert sip.left == sip.right == round(300 / 2.5332)  # VelConvFactor applies to the SIP only
    emu.feed(command(11, 0))
    emu.feed(command(21, 90))
    emu.step(1.0)
    assert next_sip(emu).thpos == 256  # 1024 steps a turn


def test_amigo_wheel_units():
    emu = opened("amigo")
    emu.feed(command(11, 300))
    sip = next_sip(emu)
    assert sip.left == sip.right == round(300 / 0.6154)


# -- sensors ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["p3dx-sh", "p3at", "amigo", "pion1m", "peoplebot-sh", "seekur"])
def test_sonar_ring_has_the_models_count(name):
    model = MODELS[name]
    emu = opened(name)
    seen: dict[int, int] = {}
    for _ in range(20):
        sip = next_sip(emu)
        assert len(sip.sonar) == min(model.sonar_count, 2 * model.sonar_arrays)
        seen.update(sip.sonar)
    assert sorted(seen) == list(range(model.sonar_count))


def test_sonar_ranges_in_the_models_units():
    emu = opened("p2at")  # RangeConvFactor 0.268
    emu.sonar = {n: 1000 + 10 * n for n in range(16)}
    seen: dict[int, int] = {}
    for _ in range(4):
        seen.update(next_sip(emu).sonar)
    assert seen == {n: round((1000 + 10 * n) / 0.268) for n in range(16)}


def test_first_sips_take_even_discs_then_odd():
    emu = opened("p3dx-sh")
    batches = [sorted(next_sip(emu).sonar) for _ in range(4)]
    assert batches == [[0, 2, 4, 6], [8, 10, 12, 14], [1, 3, 5, 7], [9, 11, 13, 15]]


@pytest.mark.parametrize(
    ("name", "optional", "front", "rear"),
    [("seekur", True, 0b11111, 0b111),
     ("powerbot", True, 0b1111111, 0b11111),
     ("p3at", True, 0b11111, 0b11111),
     ("p3at", False, 0, 0),
     ("pion1m", True, 0, 0)],
)  # fmt: skip
def test_bumper_bits_only_for_the_models_segments(name, optional, front, rear):
    emu = opened(name, optional_bumpers=optional)
    emu.front_bumpers = emu.rear_bumpers = 0x7F
    emu.stall_left = emu.stall_right = True
    sip = next_sip(emu)
    assert (sip.front_bumpers, sip.rear_bumpers) == (front, rear)
    assert sip.stall_bumpers & 0x101 == 0x101


def test_front_and_rear_rings_in_their_bytes():
    emu = opened("seekur")  # 5 front segments, 3 rear
    emu.front_bumpers = 0b00100
    assert next_sip(emu).stall_bumpers == 0b00100 << 9
    emu.front_bumpers, emu.rear_bumpers = 0, 0b010
    assert next_sip(emu).stall_bumpers == 0b010 << 1


# -- on a real link --------------------------------------------------------------------------


class PtyClient:
    def __init__(self, path: str) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.stream = b""

    def send(self, packet: bytes) -> None:
        os.write(self.fd, packet)

    async def packet(self, wanted, timeout: float = 2.0) -> bytes:
        """The next packet body for which wanted(body) holds; others are dropped."""
        deadline = asyncio.get_running_loop().time() + timeout
        while True:
            while len(self.stream) >= 3 and len(self.stream) >= 3 + self.stream[2]:
                size = 3 + self.stream[2]
                (body,) = unframe(self.stream[:size])
                self.stream = self.stream[size:]
                if wanted(body):
                    return body
            assert asyncio.get_running_loop().time() < deadline, "nothing from the emulator"
            try:
                self.stream += os.read(self.fd, 4096)
            except BlockingIOError:
                await asyncio.sleep(0.01)

    def close(self) -> None:
        os.close(self.fd)


@pytest.mark.parametrize(
    ("name", "robot_class"), [("p3at", "Pioneer"), ("pioneer-lx", "MTX"), ("p3dx-sh", "Pioneer")]
)
async def test_sync2_carries_name_class_and_subclass_on_the_wire(name, robot_class):
    emu = ArcosEmulator(name, name="rover")
    client = PtyClient(await emu.start_pty())
    try:
        for number in (0, 1):
            client.send(command(number))
            assert await client.packet(lambda b: True) == bytes([number])
        client.send(command(2))
        body = await client.packet(lambda b: True)
        assert body == b"\x02rover\0" + robot_class.encode() + b"\0" + name.encode() + b"\0"
    finally:
        client.close()
        await emu.stop()


async def test_p3at_driven_over_a_pty_reports_its_true_pose():
    emu = ArcosEmulator("p3at")
    client = PtyClient(await emu.start_pty())
    try:
        for number in (0, 1, 2):
            client.send(command(number))
            await client.packet(lambda b: True)
        client.send(command(1))
        client.send(command(4, 1))
        client.send(command(11, 500))
        await client.packet(lambda b: b[0] == 0x33)
        await asyncio.sleep(1.0)
        client.send(command(11, 0))
        await client.packet(lambda b: b[0] == 0x32)
        sip = decode_sip(await client.packet(lambda b: b[0] == 0x32))
        x, y, _ = emu.true_pose()
        assert x > 0  # how far depends on how soon the loop got to the stop: not a figure
        assert sip.xpos == round(x * 1000 / 0.465)
        assert sip.xpos * 0.465 / 1000 == pytest.approx(x, abs=0.001)
    finally:
        client.close()
        await emu.stop()
