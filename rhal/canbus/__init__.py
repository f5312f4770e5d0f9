"""CAN-bus robot bases, for ``can://`` URLs, through python-can, canopen and cantools.

    can://                                             socketcan/can0, two CiA 402 drives (default)
    can://socketcan/can0?profile=cia402&left=1&right=2
    can://slcan/dev/ttyACM0?bitrate=500000             a serial-line (SLCAN) USB adapter
    can://virtual/robot0                               python-can's in-process bus (tests)
    can://socketcan/can0?profile=dbc&dbc=/etc/robot/base.dbc&speed=BaseCommand.LinearSpeed

The URL's host is python-can's interface name and the rest of the path its channel; the
channel of a serial adapter keeps its leading slash when it is a path (``/dev/ttyACM0``).

Profiles:

``cia402``
    Two CiA 402 servo drives, one per wheel (node ids ``left`` and ``right``), driven in profile
    velocity mode through canopen's :class:`~canopen.BaseNode402`. At start-up the driver puts
    both in PRE-OPERATIONAL, checks they are CiA 402 devices, sets their heartbeat, maps its PDOs
    (RPDO1: controlword + target velocity; TPDO1: statusword + mode display; TPDO2: position
    actual + velocity actual, sent on every SYNC the driver produces), selects mode 3, starts
    them (NMT OPERATIONAL) and walks the 402 state machine to OPERATION ENABLED. A drive whose
    heartbeat stops or that leaves OPERATIONAL is a lost link: the driver starts over with
    backoff. A drive in FAULT is reported and refuses motion until the robot is opened again.

``dbc``
    A base described by a DBC file: a command message whose speed and turn-rate signals the
    driver encodes with cantools, and feedback messages it decodes. Commands are repeated at
    ``rate`` Hz while the base should move, for bases with a command timeout.

Threads: python-can reads the bus in a Notifier thread (canopen's Network runs its own); every
frame crosses into the event loop with ``loop.call_soon_threadsafe`` and the driver's state is
changed only there. Blocking calls (SDO transfers, NMT, sends, opening and shutting the bus) run
through ``asyncio.to_thread``, one at a time per robot.
"""

from rhal.canbus.cia402 import CIA402_EDS
from rhal.canbus.dbc import EXAMPLE_DBC
from rhal.canbus.profile import PROFILE_DIR
from rhal.canbus.robot import CanRobot, parse_url

__all__ = ["CIA402_EDS", "EXAMPLE_DBC", "PROFILE_DIR", "CanRobot", "parse_url"]
