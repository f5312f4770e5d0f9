"""Pioneer-family robot models: the unit conversions and geometry of each model, as ARIA has them.

Pure data, no I/O. The numbers are transcribed from the robot parameter files of ARIA, the
vendor's reference library (public copy: the AriaCoda repository, ``params/<subclass>.p``, one
file per model; the General settings, Conversion factors, Accessories and Sonar sections). Every
one of the 48 files there has an entry in MODELS; every key used below is present in every file,
so no value comes from ARIA's built-in defaults, with one exception noted at ``powerbot``.

What the factors convert (ArRobot::processMotorPacket, ArRobot::stateReflector):

- ``dist_conv`` (DistConvFactor): mm per XPOS/YPOS unit of the SIP.
- ``angle_conv`` (AngleConvFactor): radians per THPOS unit (about 2*pi/4096; 2*pi/1024 on the
  Pioneer 1 models: pion1m, pion1x, pionat, psos1m, psos1x, psos43m).
- ``vel_conv`` (VelConvFactor): mm/s per unit of L VEL and R VEL in the SIP. Commands are not
  scaled: ARIA sends VEL in mm/s and RVEL in deg/s whatever the model.
- ``range_conv`` (RangeConvFactor): mm per unit of a sonar range in the SIP.
- ``diff_conv`` (DiffConvFactor): rad/s of rotation per mm/s of half the wheel-speed difference,
  ``rot = (right - left) / 2 * diff_conv`` (after vel_conv); only used when the SIP carries no
  ROTVEL field (older firmware). ``2 / diff_conv`` is the effective wheel track in mm.
- ``vel2_divisor`` (Vel2Divisor): mm/s per unit of the VEL2 command's per-wheel bytes.

``max_velocity`` and ``max_rvelocity`` are the file's MaxVelocity (mm/s) and MaxRVelocity (deg/s),
the absolute limits ARIA uses when the robot sends no CONFIG packet. Sonar discs are listed by
sonar number, the number the SIP gives with each reading; ``front_bumpers`` and ``rear_bumpers``
are 0 when the file says the bump ring is absent (FrontBumpers/RearBumpers false), otherwise
NumFrontBumpers/NumRearBumpers.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class SonarDisc:
    x: float  # mm, forward of the centre of rotation
    y: float  # mm, to the left
    heading: float  # degrees, counter-clockwise from straight ahead


@dataclass(frozen=True)
class PioneerModel:
    subclass: str  # lower case, as ARIA names the file: "p3at", "p3dx-sh", ...
    robot_class: str  # "Pioneer", ...
    source: str  # "ARIA params/p3at.p"
    dist_conv: float  # DistConvFactor: mm per position unit (XPOS/YPOS)
    angle_conv: float  # AngleConvFactor: rad per THPOS unit
    vel_conv: float  # VelConvFactor: mm/s per wheel-velocity unit in the SIP
    range_conv: float  # RangeConvFactor: mm per sonar unit
    diff_conv: float  # DiffConvFactor
    vel2_divisor: float
    max_velocity: float  # MaxVelocity, mm/s
    max_rvelocity: float  # MaxRVelocity, deg/s
    radius: float  # mm
    width: float  # mm
    length: float  # mm
    holonomic: bool
    front_bumpers: int  # 0 if FrontBumpers is false, else NumFrontBumpers
    rear_bumpers: int  # likewise
    sonars: tuple[SonarDisc, ...]


def _ring(*discs: tuple[int, int, int]) -> tuple[SonarDisc, ...]:
    """Sonar discs from (x mm, y mm, heading deg) triples, in sonar-number order."""
    return tuple(SonarDisc(float(x), float(y), float(heading)) for x, y, heading in discs)


# fmt: off

# Sonar rings shared by several models (SonarUnit lines, x y heading).
AMIGO_RING = _ring(
    (76, 100, 90), (125, 75, 41), (150, 30, 15), (150, -30, -15),
    (125, -75, -41), (76, -100, -90), (-140, -58, -145), (-140, 58, 145),
)
AMIGO_SH_RING = _ring(
    (70, 100, 90), (125, 75, 41), (144, 30, 15), (144, -30, -15),
    (120, -75, -41), (70, -100, -90), (-146, -58, -145), (-146, 58, 145),
)
P3AT_RING = _ring(  # P2-AT, P3-AT: 8 front then 8 rear
    (147, 136, 90), (193, 119, 50), (227, 79, 30), (245, 27, 10),
    (245, -27, -10), (227, -79, -30), (193, -119, -50), (147, -136, -90),
    (-144, -136, -90), (-189, -119, -130), (-223, -79, -150), (-241, -27, -170),
    (-241, 27, 170), (-223, 79, 150), (-189, 119, 130), (-144, 136, 90),
)
P3DX_RING = _ring(  # P2-DX/DE/CE/D8, P3-DX: 8 front then 8 rear
    (69, 136, 90), (114, 119, 50), (148, 78, 30), (166, 27, 10),
    (166, -27, -10), (148, -78, -30), (114, -119, -50), (69, -136, -90),
    (-157, -136, -90), (-203, -119, -130), (-237, -78, -150), (-255, -27, -170),
    (-255, 27, 170), (-237, 78, 150), (-203, 119, 130), (-157, 136, 90),
)
_UPPER_FRONT = _ring(  # PeopleBot/Performance PeopleBot second front ring
    (-20, 136, 90), (24, 119, 50), (58, 78, 30), (77, 27, 10),
    (77, -27, -10), (58, -78, -30), (24, -119, -50), (-20, -136, -90),
)
_UPPER_REAR = _ring(  # PeopleBot/Performance PeopleBot second rear ring
    (-191, -136, -90), (-237, -119, -130), (-271, -78, -150), (-290, -27, -170),
    (-290, 27, 170), (-271, 78, 150), (-237, 119, 130), (-191, 136, 90),
)
P2PB_RING = P3DX_RING[:8] + _UPPER_FRONT + P3DX_RING[8:]  # 24: p2pb, p2pp
PEOPLEBOT_RING = P3DX_RING + _UPPER_FRONT + _UPPER_REAR  # 32: peoplebot-sh*
PERFPB_RING = P2PB_RING + _UPPER_REAR  # 32: perfpb, perfpb+ (numbered unlike peoplebot-sh)
PATROLBOT_RING = _ring(  # PatrolBot, MT400, research PatrolBot
    (83, 229, 90), (169, 202, 55), (232, 134, 30), (263, 46, 10),
    (263, -46, -10), (232, -134, -30), (169, -202, -55), (83, -229, -90),
    (-83, -229, -90), (-169, -202, -125), (-232, -134, -150), (-263, -46, -170),
    (-263, 46, 170), (-232, 134, 150), (-169, 202, 125), (-83, 229, 90),
)
PIONEER1_RING = _ring(  # Pioneer 1 (pion*, psos*): 7 front
    (100, 100, 90), (120, 80, 30), (130, 40, 15), (130, 0, 0),
    (130, -40, -15), (120, -80, -30), (100, -100, -90),
)
PIONEER_LX_RING = _ring(  # on the LX's MTX sonar board, not reported in the SIP
    (331, 61, 10), (331, -61, -10), (-317, 90, 164), (-317, -90, -164),
)
POWERBOT_RING = _ring(  # 4 banks of 8; the (0, 0, -180) units are unused channels
    (152, 278, 90), (200, 267, 65), (241, 238, 45), (274, 200, 35),
    (300, 153, 25), (320, 96, 15), (332, 33, 5), (0, 0, -180),
    (332, -33, -5), (320, -96, -15), (300, -153, -25), (274, -200, -35),
    (241, -238, -45), (200, -267, -65), (152, -278, -90), (0, 0, -180),
    (-298, -278, -90), (-347, -267, -115), (-388, -238, -135), (-420, -200, -145),
    (-447, -153, -155), (-467, -96, -165), (-478, -33, -175), (0, 0, -180),
    (-478, 33, 175), (-467, 96, 165), (-447, 153, 155), (-420, 200, 145),
    (-388, 238, 135), (-347, 267, 115), (-298, 278, 90), (0, 0, -180),
)
POWERBOT_REAR_RING = POWERBOT_RING[16:]  # powerbot-sh-uarcs: the rear banks, renumbered 0-15
# params/powerbot.p says SonarNum 32 but has no SonarUnit 31 (nor does ARIA's built-in PowerBot
# default); ArRobotParams::getSonarX/Y/Th answer 0 for a unit missing from the file, so ARIA
# places sonar 31 at (0, 0, 0).
_POWERBOT_P_RING = POWERBOT_RING[:31] + (SonarDisc(0.0, 0.0, 0.0),)
NO_SONAR: tuple[SonarDisc, ...] = ()

# Conversion factors section, keyed by parameter file name (params/<name>.p):
#                         DistConv AngleConv VelConv RangeConv DiffConv Vel2Divisor
_CONVERSION: dict[str, tuple[float, float, float, float, float, float]] = {
    "amigo":               (0.5083,  0.00153,  0.6154,  1.0,    0.011,    20.0),
    "amigo-sh":            (1.0,     0.00153,  1.0,     1.0,    0.011,    20.0),
    "amigo-sh-tim3xx":     (1.0,     0.00153,  1.0,     1.0,    0.011,    20.0),
    "mt400":               (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "p2at":                (1.32,    0.00153,  1.0,     0.268,  0.0034,   20.0),
    "p2at8":               (1.32,    0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p2at8+":              (0.465,   0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p2ce":                (0.826,   0.00153,  1.0,     0.268,  0.0057,   20.0),
    "p2d8":                (0.485,   0.00153,  1.0,     1.0,    0.0056,   20.0),
    "p2d8+":               (0.485,   0.00153,  1.0,     1.0,    0.0056,   20.0),
    "p2de":                (0.969,   0.00153,  1.0,     0.268,  0.0056,   20.0),
    "p2df":                (0.485,   0.00153,  1.0,     0.268,  0.006,    20.0),
    "p2dx":                (0.84,    0.00153,  1.0,     0.268,  0.0056,   20.0),
    "p2it":                (1.136,   0.00153,  1.0,     0.268,  0.0032,   20.0),
    "p2pb":                (0.424,   0.00153,  1.0,     0.268,  0.0056,   20.0),
    "p2pp":                (0.485,   0.00153,  1.0,     0.268,  0.006,    20.0),
    "p3at":                (0.465,   0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p3at-sh":             (1.0,     0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p3at-sh-lms1xx":      (1.0,     0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p3at-sh-lms500":      (1.0,     0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p3atiw-sh":           (1.0,     0.00153,  1.0,     1.0,    0.0034,   20.0),
    "p3dx":                (0.485,   0.00153,  1.0,     1.0,    0.0056,   20.0),
    "p3dx-sh":             (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "p3dx-sh-lms1xx":      (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "p3dx-sh-lms500":      (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "patrolbot-sh":        (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "peoplebot-sh":        (1.0,     0.00153,  1.0,     1.0,    0.006,    20.0),
    "peoplebot-sh-lms1xx": (1.0,     0.00153,  1.0,     1.0,    0.006,    20.0),
    "peoplebot-sh-lms500": (1.0,     0.00153,  1.0,     1.0,    0.006,    20.0),
    "perfpb":              (0.485,   0.00153,  1.0,     1.0,    0.006,    20.0),
    "perfpb+":             (0.485,   0.00153,  1.0,     1.0,    0.006,    20.0),
    "pion1m":              (0.05066, 0.00614,  2.5332,  0.1734, 0.00333,  4.0),
    "pion1x":              (0.05066, 0.00614,  2.5332,  0.1734, 0.00333,  4.0),
    "pionat":              (0.07,    0.00614,  2.5332,  0.1734, 0.00333,  4.0),
    "pioneer-lx":          (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "pioneer-lx-ld":       (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "powerbot":            (0.5813,  0.00153,  1.0,     1.0,    0.00373,  20.0),
    "powerbot-sh":         (1.0,     0.00153,  1.0,     1.0,    0.00373,  20.0),
    "powerbot-sh-lms500":  (1.0,     0.00153,  1.0,     1.0,    0.00373,  20.0),
    "powerbot-sh-uarcs":   (1.0,     0.00153,  1.0,     1.0,    0.00373,  20.0),
    "psos1m":              (0.05066, 0.00614,  2.5332,  0.1734, 0.00333,  4.0),
    "psos1x":              (0.05066, 0.00614,  2.5332,  0.1734, 0.00333,  4.0),
    "psos43m":             (0.05066, 0.00614,  2.5332,  0.1734, 0.00333,  4.0),
    "researchPB":          (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "researchPB-lms500":   (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "seekur":              (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "seekurjr":            (1.0,     0.00153,  1.0,     1.0,    0.0056,   20.0),
    "wheelchair-sh":       (1.0,     0.00153,  1.0,     1.0,    0.00373,  20.0),
}

# General settings, Accessories and Sonar sections, same keys:
#                         Class      MaxVel MaxRVel Radius Width Length Holonomic
#                                                                  front, rear bumpers, sonars
_BODY: dict[str, tuple[str, int, int, int, int, int, bool, int, int, tuple[SonarDisc, ...]]] = {
    "amigo":               ("Pioneer", 1000, 300, 180, 279,  330,  True, 0, 0, AMIGO_RING),
    "amigo-sh":            ("Pioneer", 1000, 300, 180, 279,  330,  True, 0, 0, AMIGO_SH_RING),
    "amigo-sh-tim3xx":     ("Pioneer", 1000, 300, 180, 279,  330,  True, 0, 0, AMIGO_SH_RING),
    "mt400":               ("Pioneer", 2200, 500, 250, 425,  510,  True, 6, 6, PATROLBOT_RING),
    "p2at":                ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p2at8":               ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p2at8+":              ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p2ce":                ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p2d8":                ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p2d8+":               ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p2de":                ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p2df":                ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p2dx":                ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p2it":                ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p2pb":                ("Pioneer", 2200, 500, 300, 425,  513,  True, 5, 5, P2PB_RING),
    "p2pp":                ("Pioneer", 2200, 500, 300, 425,  513,  True, 5, 5, P2PB_RING),
    "p3at":                ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p3at-sh":             ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p3at-sh-lms1xx":      ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p3at-sh-lms500":      ("Pioneer", 1200, 300, 500, 505,  626,  True, 0, 0, P3AT_RING),
    "p3atiw-sh":           ("Pioneer", 1200, 300, 500, 490,  626,  True, 0, 0, P3AT_RING),
    "p3dx":                ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p3dx-sh":             ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p3dx-sh-lms1xx":      ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "p3dx-sh-lms500":      ("Pioneer", 2200, 500, 250, 425,  511,  True, 0, 0, P3DX_RING),
    "patrolbot-sh":        ("Pioneer", 2200, 500, 250, 425,  510,  True, 6, 6, PATROLBOT_RING),
    "peoplebot-sh":        ("Pioneer", 2200, 500, 340, 425,  513,  True, 5, 5, PEOPLEBOT_RING),
    "peoplebot-sh-lms1xx": ("Pioneer", 2200, 500, 340, 425,  513,  True, 5, 5, PEOPLEBOT_RING),
    "peoplebot-sh-lms500": ("Pioneer", 2200, 500, 340, 425,  513,  True, 5, 5, PEOPLEBOT_RING),
    "perfpb":              ("Pioneer", 2200, 500, 340, 425,  513,  True, 5, 5, PERFPB_RING),
    "perfpb+":             ("Pioneer", 2200, 500, 340, 425,  511,  True, 5, 5, PERFPB_RING),
    "pion1m":              ("Pioneer", 400,  100, 220, 400,  500,  True, 0, 0, PIONEER1_RING),
    "pion1x":              ("Pioneer", 400,  100, 220, 400,  500,  True, 0, 0, PIONEER1_RING),
    "pionat":              ("Pioneer", 500,  100, 330, 400,  500,  True, 0, 0, PIONEER1_RING),
    "pioneer-lx":          ("MTX",     2500, 180, 348, 500,  696,  True, 3, 3, PIONEER_LX_RING),
    "pioneer-lx-ld":       ("MTX",     2500, 180, 348, 500,  696,  True, 3, 3, PIONEER_LX_RING),
    "powerbot":            ("Pioneer", 2000, 360, 550, 680,  911,  True, 7, 5, _POWERBOT_P_RING),
    "powerbot-sh":         ("Pioneer", 2000, 360, 550, 680,  911,  True, 7, 5, POWERBOT_RING),
    "powerbot-sh-lms500":  ("Pioneer", 2000, 360, 550, 680,  911,  True, 7, 5, POWERBOT_RING),
    "powerbot-sh-uarcs":   ("Pioneer", 2000, 360, 550, 680,  911,  True, 7, 5, POWERBOT_REAR_RING),
    "psos1m":              ("Pioneer", 400,  100, 220, 400,  500,  True, 0, 0, PIONEER1_RING),
    "psos1x":              ("Pioneer", 400,  100, 220, 400,  500,  True, 0, 0, PIONEER1_RING),
    "psos43m":             ("Pioneer", 400,  100, 220, 400,  500,  True, 0, 0, PIONEER1_RING),
    "researchPB":          ("Pioneer", 2200, 500, 250, 425,  510,  True, 6, 6, PATROLBOT_RING),
    "researchPB-lms500":   ("Pioneer", 2200, 500, 250, 425,  510,  True, 6, 6, PATROLBOT_RING),
    "seekur":              ("Pioneer", 2200, 190, 833, 1270, 1410, True, 5, 3, NO_SONAR),
    "seekurjr":            ("Pioneer", 1200, 80,  600, 830,  1200, True, 4, 4, NO_SONAR),
    "wheelchair-sh":       ("Pioneer", 2000, 360, 550, 680,  1340, True, 4, 3, NO_SONAR),
}

# fmt: on


def _build() -> dict[str, PioneerModel]:
    models = {}
    for name, (dist, angle, vel, rng, diff, vel2) in _CONVERSION.items():
        cls, maxv, maxrv, radius, width, length, holonomic, front, rear, sonars = _BODY[name]
        # ARIA lowercases the SYNC2 subclass, so "researchPB.p" is reached as "researchpb".
        subclass = name.lower()
        models[subclass] = PioneerModel(
            subclass=subclass,
            robot_class=cls,
            source=f"ARIA params/{name}.p",
            dist_conv=dist,
            angle_conv=angle,
            vel_conv=vel,
            range_conv=rng,
            diff_conv=diff,
            vel2_divisor=vel2,
            max_velocity=float(maxv),
            max_rvelocity=float(maxrv),
            radius=float(radius),
            width=float(width),
            length=float(length),
            holonomic=holonomic,
            front_bumpers=front,
            rear_bumpers=rear,
            sonars=sonars,
        )
    return models


MODELS: dict[str, PioneerModel] = _build()

# Subtypes ARIA (ArRobot::madeConnection) also treats as a Pioneer LX: "marc_devel" from early
# MTX firmware (ARIA loads pioneer-lx.p for it), "lx" from MobileSim 0.7.2, and "lynx".
_ALIASES = {"lx": "pioneer-lx", "marc_devel": "pioneer-lx", "lynx": "pioneer-lx"}


def model_for(subclass: str) -> PioneerModel | None:
    """The model for a SYNC2 subclass string, ignoring case as ARIA does; None if ARIA has none."""
    key = subclass.lower()
    return MODELS.get(_ALIASES.get(key, key))
