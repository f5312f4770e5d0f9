"""The ARCOS robot emulator's own table of Pioneer-family models.

Transcribed by hand from the vendor's robot parameter files, one per model, in ARIA
(repository reedhedges/AriaCoda, ``params/<subclass>.p``), NOT from our driver: the driver's
table (``rhal/pioneer_models.py``) is written separately, so the two check each other.

What each number means, as ARIA reads a SIP (``src/ArRobot.cpp``, ``processMotorPacket``):

* ``dist_conv`` (DistConvFactor): mm per XPOS/YPOS unit. XPOS/YPOS are 15-bit counters.
* ``angle_conv`` (AngleConvFactor): rad per THPOS unit, as printed in the file (5 decimals).
  The files' own comment says "2PI/4096", ARIA's built-in default is 0.001534 and its
  built-in Pioneer 1 value 0.0061359 (= 2 pi / 1024); the simulator AMRISim uses the same
  two numbers. So THPOS counts ``angle_units_per_turn`` per revolution (4096, or 1024 on the
  Pioneer 1 / PSOS robots) and 0.00153 / 0.00614 are those steps rounded.
* ``vel_conv`` (VelConvFactor): mm/s per unit of the SIP's left/right wheel velocities. It does
  not apply to commands: ARIA sends VEL in mm/s and RVEL in deg/s on every model.
* ``range_conv`` (RangeConvFactor): mm per sonar range unit.
* ``diff_conv`` (DiffConvFactor): ARIA's turn rate from the wheels is
  ``omega [rad/s] = (right - left) / 2 * diff_conv`` (wheel speeds in mm/s), so each wheel
  runs ``omega / diff_conv`` mm/s faster or slower than the middle: 1 / diff_conv is half the
  effective track in mm.
* ``max_vel`` / ``max_rvel`` (MaxVelocity, mm/s / MaxRVelocity, deg/s): ARIA's absolute maxima.
* ``sonar_count`` (SonarNum) and ``sonar_poses`` ((x mm, y mm, heading deg) per disc from the
  SonarUnit lines; ``None`` where the file lists no SonarUnit for a disc it counts).
* ``front_bumpers`` / ``rear_bumpers``: NumFrontBumpers / NumRearBumpers when the file says the
  ring is fitted (FrontBumpers / RearBumpers true), else 0. ``optional_*_bumpers`` keeps the
  ring size the file gives for a ring it marks absent (an optional accessory on P2/P3 bases).

The ``-lms1xx``, ``-lms500`` and ``-tim3xx`` files and ``pioneer-lx-ld`` were compared with
their base model and differ only in laser settings (and, for ``pioneer-lx-ld``, the MTX sonar
"autonomous driving" flags), so they are not repeated here. ``powerbot-sh-uarcs`` is not a
laser variant (it has 16 sonar, the rear ring only) and has its own entry.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

REPOSITORY = "reedhedges/AriaCoda"

# x mm (+ forward), y mm (+ left), heading of the disc in degrees (+ counter-clockwise)
Pose = tuple[int, int, int]


@dataclass(frozen=True)
class ArcosModel:
    subclass: str  # SYNC2's third string, and the name of the parameter file
    robot_class: str  # SYNC2's second string
    dist_conv: float
    angle_conv: float
    vel_conv: float
    range_conv: float
    diff_conv: float
    max_vel: int  # mm/s
    max_rvel: int  # deg/s
    sonar_count: int
    sonar_poses: tuple[Pose | None, ...]
    front_bumpers: int
    rear_bumpers: int
    optional_front_bumpers: int = 0
    optional_rear_bumpers: int = 0
    angle_units_per_turn: int = 4096
    note: str = ""

    @property
    def source(self) -> str:
        return f"{REPOSITORY}: params/{self.subclass}.p"

    @property
    def sonar_arrays(self) -> int:
        """Banks of up to eight discs, each polled one disc at a time by the firmware."""
        return -(-self.sonar_count // 8)


# Sonar rings, each checked line by line against every file that uses it.

# P2-AT / P3-AT bodies: p2at, p2at8, p2at8+, p2it, p3at, p3at-sh, p3atiw-sh.
AT_16: tuple[Pose, ...] = (
    (147, 136, 90), (193, 119, 50), (227, 79, 30), (245, 27, 10),
    (245, -27, -10), (227, -79, -30), (193, -119, -50), (147, -136, -90),
    (-144, -136, -90), (-189, -119, -130), (-223, -79, -150), (-241, -27, -170),
    (-241, 27, 170), (-223, 79, 150), (-189, 119, 130), (-144, 136, 90),
)  # fmt: skip

# P2-DX / P3-DX bodies: p2ce, p2d8, p2d8+, p2de, p2df, p2dx, p3dx, p3dx-sh.
DX_FRONT_8: tuple[Pose, ...] = (
    (69, 136, 90), (114, 119, 50), (148, 78, 30), (166, 27, 10),
    (166, -27, -10), (148, -78, -30), (114, -119, -50), (69, -136, -90),
)  # fmt: skip
DX_REAR_8: tuple[Pose, ...] = (
    (-157, -136, -90), (-203, -119, -130), (-237, -78, -150), (-255, -27, -170),
    (-255, 27, 170), (-237, 78, 150), (-203, 119, 130), (-157, 136, 90),
)  # fmt: skip
DX_16 = DX_FRONT_8 + DX_REAR_8

# The PeopleBot's upper front ring and its second rear ring.
PB_UPPER_FRONT_8: tuple[Pose, ...] = (
    (-20, 136, 90), (24, 119, 50), (58, 78, 30), (77, 27, 10),
    (77, -27, -10), (58, -78, -30), (24, -119, -50), (-20, -136, -90),
)  # fmt: skip
PB_UPPER_REAR_8: tuple[Pose, ...] = (
    (-191, -136, -90), (-237, -119, -130), (-271, -78, -150), (-290, -27, -170),
    (-290, 27, 170), (-271, 78, 150), (-237, 119, 130), (-191, 136, 90),
)  # fmt: skip
PB_24 = DX_FRONT_8 + PB_UPPER_FRONT_8 + DX_REAR_8  # p2pb, p2pp
PERFPB_32 = PB_24 + PB_UPPER_REAR_8  # perfpb, perfpb+
PEOPLEBOT_SH_32 = DX_16 + PB_UPPER_FRONT_8 + PB_UPPER_REAR_8  # note: a different order

# PowerBot: discs 7, 15, 23 (and 31 on powerbot-sh) are listed at 0 0 -180.
POWERBOT_30: tuple[Pose, ...] = (
    (152, 278, 90), (200, 267, 65), (241, 238, 45), (274, 200, 35),
    (300, 153, 25), (320, 96, 15), (332, 33, 5), (0, 0, -180),
    (332, -33, -5), (320, -96, -15), (300, -153, -25), (274, -200, -35),
    (241, -238, -45), (200, -267, -65), (152, -278, -90), (0, 0, -180),
    (-298, -278, -90), (-347, -267, -115), (-388, -238, -135), (-420, -200, -145),
    (-447, -153, -155), (-467, -96, -165), (-478, -33, -175), (0, 0, -180),
    (-478, 33, 175), (-467, 96, 165), (-447, 153, 155), (-420, 200, 145),
    (-388, 238, 135), (-347, 267, 115), (-298, 278, 90),
)  # fmt: skip
POWERBOT_UARCS_16: tuple[Pose, ...] = (
    (-298, -278, -90), (-347, -267, -115), (-388, -238, -135), (-420, -200, -145),
    (-447, -153, -155), (-467, -96, -165), (-478, -33, -175), (0, 0, -180),
    (-478, 33, 175), (-467, 96, 165), (-447, 153, 155), (-420, 200, 145),
    (-388, 238, 135), (-347, 267, 115), (-298, 278, 90), (0, 0, -180),
)  # fmt: skip

# PatrolBot body: patrolbot-sh, mt400, researchPB.
PATROL_16: tuple[Pose, ...] = (
    (83, 229, 90), (169, 202, 55), (232, 134, 30), (263, 46, 10),
    (263, -46, -10), (232, -134, -30), (169, -202, -55), (83, -229, -90),
    (-83, -229, -90), (-169, -202, -125), (-232, -134, -150), (-263, -46, -170),
    (-263, 46, 170), (-232, 134, 150), (-169, 202, 125), (-83, 229, 90),
)  # fmt: skip

AMIGO_8: tuple[Pose, ...] = (
    (76, 100, 90), (125, 75, 41), (150, 30, 15), (150, -30, -15),
    (125, -75, -41), (76, -100, -90), (-140, -58, -145), (-140, 58, 145),
)  # fmt: skip
AMIGO_SH_8: tuple[Pose, ...] = (  # disc 4 at x 120 while disc 1 is at 125: as in the file
    (70, 100, 90), (125, 75, 41), (144, 30, 15), (144, -30, -15),
    (120, -75, -41), (70, -100, -90), (-146, -58, -145), (-146, 58, 145),
)  # fmt: skip

# Pioneer 1 / PSOS bodies: pion1m, pion1x, pionat, psos1m, psos1x, psos43m.
P1_7: tuple[Pose, ...] = (
    (100, 100, 90), (120, 80, 30), (130, 40, 15), (130, 0, 0),
    (130, -40, -15), (120, -80, -30), (100, -100, -90),
)  # fmt: skip

# Pioneer LX: an MTX sonar board (its own serial port in ARIA), four discs.
LX_4: tuple[Pose, ...] = ((331, 61, 10), (331, -61, -10), (-317, 90, 164), (-317, -90, -164))


def _model(
    subclass: str,
    conv: tuple[float, float, float, float, float],
    top: tuple[int, int],
    sonar: tuple[Pose | None, ...],
    bumpers: tuple[int, int],
    optional: tuple[int, int] = (0, 0),
    *,
    robot_class: str = "Pioneer",
    sonar_count: int | None = None,
    units_per_turn: int = 4096,
    note: str = "",
) -> ArcosModel:
    """conv: (Dist, Angle, Vel, Range, Diff)ConvFactor; top: (MaxVelocity, MaxRVelocity)."""
    count = len(sonar) if sonar_count is None else sonar_count
    poses = tuple(sonar) + (None,) * (count - len(sonar))
    dist, angle, vel, rng, diff = conv
    return ArcosModel(
        subclass, robot_class, dist, angle, vel, rng, diff, top[0], top[1], count, poses,
        bumpers[0], bumpers[1], optional[0], optional[1], units_per_turn, note,
    )  # fmt: skip


OPT5 = (5, 5)  # NumFront/NumRearBumpers in files that mark both rings absent
P1 = dict(units_per_turn=1024)  # Pioneer 1 / PSOS: THPOS in 1024ths of a turn

# Columns: subclass, (Dist, Angle, Vel, Range, Diff)ConvFactor, (MaxVelocity, MaxRVelocity),
# sonar ring, (front, rear) bumpers fitted, (front, rear) optional ring sizes.
_MODELS = [
    _model("p2at", (1.32, 0.00153, 1.0, 0.268, 0.0034), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p2at8", (1.32, 0.00153, 1.0, 1.0, 0.0034), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p2at8+", (0.465, 0.00153, 1.0, 1.0, 0.0034), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p2ce", (0.826, 0.00153, 1.0, 0.268, 0.0057), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p2d8", (0.485, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p2d8+", (0.485, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p2de", (0.969, 0.00153, 1.0, 0.268, 0.0056), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p2df", (0.485, 0.00153, 1.0, 0.268, 0.006), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p2dx", (0.84, 0.00153, 1.0, 0.268, 0.0056), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p2it", (1.136, 0.00153, 1.0, 0.268, 0.0032), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p2pb", (0.424, 0.00153, 1.0, 0.268, 0.0056), (2200, 500), PB_24, (5, 5)),
    _model("p2pp", (0.485, 0.00153, 1.0, 0.268, 0.006), (2200, 500), PB_24, (5, 5)),
    _model("p3at", (0.465, 0.00153, 1.0, 1.0, 0.0034), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p3at-sh", (1.0, 0.00153, 1.0, 1.0, 0.0034), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p3atiw-sh", (1.0, 0.00153, 1.0, 1.0, 0.0034), (1200, 300), AT_16, (0, 0), OPT5),
    _model("p3dx", (0.485, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), DX_16, (0, 0), OPT5),
    _model("p3dx-sh", (1.0, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), DX_16, (0, 0), OPT5),
    _model("peoplebot-sh", (1.0, 0.00153, 1.0, 1.0, 0.006), (2200, 500), PEOPLEBOT_SH_32, (5, 5)),
    _model("powerbot", (0.5813, 0.00153, 1.0, 1.0, 0.00373), (2000, 360), POWERBOT_30, (7, 5),
           sonar_count=32, note="SonarNum 32 but no SonarUnit line for disc 31"),
    _model("powerbot-sh", (1.0, 0.00153, 1.0, 1.0, 0.00373), (2000, 360),
           POWERBOT_30 + ((0, 0, -180),), (7, 5)),
    _model("powerbot-sh-uarcs", (1.0, 0.00153, 1.0, 1.0, 0.00373), (2000, 360),
           POWERBOT_UARCS_16, (7, 5)),
    _model("amigo", (0.5083, 0.00153, 0.6154, 1.0, 0.011), (1000, 300), AMIGO_8, (0, 0), OPT5),
    _model("amigo-sh", (1.0, 0.00153, 1.0, 1.0, 0.011), (1000, 300), AMIGO_SH_8, (0, 0), OPT5),
    _model("patrolbot-sh", (1.0, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), PATROL_16, (6, 6)),
    _model("mt400", (1.0, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), PATROL_16, (6, 6)),
    _model("researchPB", (1.0, 0.00153, 1.0, 1.0, 0.0056), (2200, 500), PATROL_16, (6, 6)),
    _model("pioneer-lx", (1.0, 0.00153, 1.0, 1.0, 0.0056), (2500, 180), LX_4, (3, 3),
           robot_class="MTX", note="sonar on an MTX sonar board (its own serial port in ARIA); "
           "the file's TransVelMax is 1800 and RotVelMax 180"),
    _model("seekur", (1.0, 0.00153, 1.0, 1.0, 0.0056), (2200, 190), (), (5, 3),
           note="MaxLatVelocity 2200, HasLatVel true"),
    _model("seekurjr", (1.0, 0.00153, 1.0, 1.0, 0.0056), (1200, 80), (), (4, 4)),
    _model("wheelchair-sh", (1.0, 0.00153, 1.0, 1.0, 0.00373), (2000, 360), (), (4, 3)),
    _model("perfpb", (0.485, 0.00153, 1.0, 1.0, 0.006), (2200, 500), PERFPB_32, (5, 5)),
    _model("perfpb+", (0.485, 0.00153, 1.0, 1.0, 0.006), (2200, 500), PERFPB_32, (5, 5)),
    _model("pion1m", (0.05066, 0.00614, 2.5332, 0.1734, 0.00333), (400, 100), P1_7, (0, 0), **P1),
    _model("pion1x", (0.05066, 0.00614, 2.5332, 0.1734, 0.00333), (400, 100), P1_7, (0, 0), **P1),
    _model("pionat", (0.07, 0.00614, 2.5332, 0.1734, 0.00333), (500, 100), P1_7, (0, 0), **P1,
           note="the file's TransVelMax is 400, below its MaxVelocity 500"),
    _model("psos1m", (0.05066, 0.00614, 2.5332, 0.1734, 0.00333), (400, 100), P1_7, (0, 0), **P1),
    _model("psos1x", (0.05066, 0.00614, 2.5332, 0.1734, 0.00333), (400, 100), P1_7, (0, 0), **P1),
    _model("psos43m", (0.05066, 0.00614, 2.5332, 0.1734, 0.00333), (400, 100), P1_7, (0, 0), **P1),
]  # fmt: skip

# Files that differ from their base model only in the laser (or sonar board) fitted: the same
# robot on the wire.
_LASER_VARIANTS = {
    "amigo-sh-tim3xx": "amigo-sh",
    "p3at-sh-lms1xx": "p3at-sh",
    "p3at-sh-lms500": "p3at-sh",
    "p3dx-sh-lms1xx": "p3dx-sh",
    "p3dx-sh-lms500": "p3dx-sh",
    "peoplebot-sh-lms1xx": "peoplebot-sh",
    "peoplebot-sh-lms500": "peoplebot-sh",
    "pioneer-lx-ld": "pioneer-lx",
    "powerbot-sh-lms500": "powerbot-sh",
    "researchPB-lms500": "researchPB",
}
MODELS: dict[str, ArcosModel] = {model.subclass: model for model in _MODELS}
MODELS.update(
    {name: replace(MODELS[base], subclass=name) for name, base in _LASER_VARIANTS.items()}
)


def get_model(model: str | ArcosModel) -> ArcosModel:
    if isinstance(model, ArcosModel):
        return model
    try:
        return MODELS[model]
    except KeyError:
        raise ValueError(f"no ARCOS model {model!r}; known: {', '.join(sorted(MODELS))}") from None
