"""The robot drivers' option help (rhal's ``option_help``, shown on a robot's page and its
settings form) in the reader's language.

rhal has no Django: its texts are msgids here, translated where shown (robots.driver_settings).
tests/test_i18n_complete.py fails when a driver's option help is missing here.
"""

from dataclasses import replace

from django.utils.translation import gettext, gettext_noop

TEXTS = (
    gettext_noop("speed limit, m/s: faster drive() calls are clamped to it"),
    gettext_noop("turn-rate limit, rad/s"),
    gettext_noop("the walled arena the robot starts in"),
    gettext_noop("the language of the words drawn on its camera's picture"),
    gettext_noop(
        "the world it runs in: a built-in one (boxes, square, maze, line, rooms) or a stored "
        "world's name or number"
    ),
    gettext_noop("the old name of the world option"),
    gettext_noop("how many times faster than real time it runs, 1 to 10"),
    gettext_noop(
        "angles of a sonar ring, degrees to the left of ahead (90,45,0,-45,-90); blank: the "
        "world's robot's"
    ),
    gettext_noop("a floor colour sensor under its nose; blank: the world's robot's"),
    gettext_noop("the range sensor's beam width, degrees; blank: the world's robot's"),
    gettext_noop("record the tones to this WAV file instead of playing them"),
    gettext_noop("sound device name or index (blank: the system's output)"),
    gettext_noop("Hz (blank: 8000 for a WAV, 44100 for a device)"),
    gettext_noop("length of each tone, ms"),
    gettext_noop("silence between tones, ms"),
    gettext_noop("tone level, 0..1 of full scale"),
    gettext_noop("digit table: mt8870, or state:digit pairs (forward:2,back:8,...)"),
    gettext_noop("fraction of the speed limits below which drive() means stop"),
    gettext_noop("times the stop digit is sent on each stop"),
    gettext_noop("serial speed, bit/s (ignored on TCP)"),
    gettext_noop("s without a packet before the link counts as lost"),
    gettext_noop("s between keep-alive PULSEs for the robot's watchdog"),
    gettext_noop("a compass is fitted: heading comes from it instead of odometry"),
    gettext_noop("ARIA model whose units to use; blank: the one the robot names"),
    gettext_noop("mm per position unit; blank: the model's DistConvFactor"),
    gettext_noop("rad per heading unit; blank: the model's AngleConvFactor"),
    gettext_noop("mm/s per wheel-speed unit; blank: the model's VelConvFactor"),
    gettext_noop("mm per sonar unit; blank: the model's RangeConvFactor"),
    gettext_noop("m, effective wheel track; blank: 2 / the model's DiffConvFactor"),
    gettext_noop("sonar discs reported; blank: the model's ring"),
    gettext_noop("front bump-ring segments; blank: the model's (0: none fitted)"),
    gettext_noop("rear bump-ring segments; blank: the model's (0: none fitted)"),
    gettext_noop("output port of the left wheel's motor"),
    gettext_noop("output port of the right wheel's motor"),
    gettext_noop("the left motor is mounted backwards"),
    gettext_noop("the right motor is mounted backwards"),
    gettext_noop("m: 0.056 for the standard NXT wheel"),
    gettext_noop("m between the wheels' centres"),
    gettext_noop("sensor port (1-4) of the ultrasonic sensor; blank: none"),
    gettext_noop("sensor port of a touch sensor (read as the bumper); blank: none"),
    gettext_noop("sensor port of a light sensor; blank: none"),
    gettext_noop("sensor port of a sound sensor; blank: none"),
    gettext_noop("light the light sensor's lamp (reflected light) or not (ambient)"),
    gettext_noop("stop by braking the motors; off: let them coast"),
    gettext_noop("Hz: how often the motors and sensors are read"),
    gettext_noop("s to wait for a reply before the link counts as lost"),
    gettext_noop("s between KeepAlives, which keep the brick from switching itself off"),
    gettext_noop("serial speed, bit/s (ignored on TCP and UDP; 57600 for most telemetry radios)"),
    gettext_noop("s without a HEARTBEAT from the vehicle before the link counts as lost"),
    gettext_noop("switch to GUIDED/OFFBOARD and arm on the first motion; off: a person does it"),
    gettext_noop("s to keep retrying a refused mode switch or arming before giving up"),
    gettext_noop("Hz at which velocity setpoints are streamed (2 to 50)"),
    gettext_noop("our MAVLink system id (set ArduPilot's SYSID_MYGCS to it for the GCS failsafe)"),
    gettext_noop("disarm the vehicle on close, if the driver armed it"),
    gettext_noop(
        "UDP: listen on the URL's address (on) or send to it (off); default: listen "
        "when the host is empty"
    ),
    gettext_noop("cia402: two CiA 402 wheel drives; dbc: a base described by a DBC file"),
    gettext_noop(
        "bit/s, for interfaces that set it (slcan, pcan...); socketcan's is set with ip link"
    ),
    gettext_noop(
        "s of silence (no heartbeat / no feedback frame) before the link counts as "
        "lost; blank: 0.5 for cia402, 1 for dbc"
    ),
    gettext_noop("cia402: node id of the left wheel's drive"),
    gettext_noop("cia402: node id of the right wheel's drive"),
    gettext_noop("cia402: the drives' EDS file (blank: the generic CiA 402 one shipped)"),
    gettext_noop("cia402: m between the wheels' contact points"),
    gettext_noop("cia402: position counts (0x6064) per wheel turn, gearbox included"),
    gettext_noop(
        "cia402: position counts per metre of travel (blank: from counts_per_rev and "
        "wheel_diameter)"
    ),
    gettext_noop(
        "cia402: units of 0x60FF/0x606C per m/s (blank: counts_per_metre, for drives "
        "whose velocity is in counts/s)"
    ),
    gettext_noop("cia402: the left drive turns the wheel backwards for a positive speed"),
    gettext_noop(
        "cia402: the right drive turns the wheel backwards for a positive speed "
        "(usual: it is mounted mirrored)"
    ),
    gettext_noop("cia402: s between the drives' heartbeats (0x1017)"),
    gettext_noop(
        "cia402: s between the SYNCs the driver sends; the drives answer each with their TPDOs"
    ),
    gettext_noop("dbc: the base's DBC file (blank: the example base shipped)"),
    gettext_noop("dbc: the message the driver sends"),
    gettext_noop("dbc: Message.Signal for the forward speed the driver sends"),
    gettext_noop("dbc: Message.Signal for the turn rate (counter-clockwise) the driver sends"),
    gettext_noop("dbc: Message.Signal of the measured forward speed"),
    gettext_noop("dbc: Message.Signal of the measured turn rate"),
    gettext_noop("dbc: Message.Signal of a compass heading, degrees (blank: none)"),
    gettext_noop("dbc: Message.Signal of the battery voltage (blank: none)"),
    gettext_noop("dbc: Message.Signal of the distance ahead (blank: none)"),
    gettext_noop("dbc: Hz at which a command is repeated while moving (0: sent once)"),
)


def option_shown(option):
    """A driver's Option (rhal.options) with its help in the active language."""
    return replace(option, help=gettext(option.help)) if option.help else option
