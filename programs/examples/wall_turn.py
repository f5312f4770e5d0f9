"""Drive to the wall, turn away from it, and tell the heading."""

import time

import robot

bot = robot.Robot()

bot.drive(0.3, 0.0)
while bot.sensors()["range"] >= 0.5:  # metres
    time.sleep(0.02)
bot.stop()

bot.drive(0.0, 1.0)  # turn at 1 rad/s
time.sleep(1.5)
bot.stop()

heading = round(bot.sensors()["heading"], 1)
print(f"heading: {heading:.1f}")
bot.show("heading", heading)
