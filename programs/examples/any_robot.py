"""The same program on any robot: drive forward 1 s, turn, stop, and say what it senses.

Only the robot behind the API changes: a simulation, a DTMF tone robot, a Lego NXT, a Pioneer,
a MAVLink rover or a CAN-bus base. Sensors a robot lacks are skipped, not an error.
"""

import time

import robot

bot = robot.Robot()
has = bot.capabilities()["sensors"]

bot.drive(0.2, 0.0)  # forward at 0.2 m/s
time.sleep(1.0)
bot.drive(0.0, 1.0)  # turn left at 1 rad/s
time.sleep(1.0)
bot.stop()

print("stopped on a", bot.capabilities()["kind"], "robot")
readings = bot.sensors()
for name in ("heading", "range"):
    if name not in has:
        print(f"{name}: this robot has no such sensor")
    elif readings[name] is None:
        print(f"{name}: no reading")
    else:
        print(f"{name}: {readings[name]:.2f} {has[name]['unit']}")
