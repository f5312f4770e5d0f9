"""Drive ahead and stop before the wall, using the range sensor."""

import time

import robot

bot = robot.Robot()
STOP_AT = 0.5  # metres

bot.drive(0.3, 0.0)
while True:
    distance = bot.sensors()["range"]
    bot.show("range", round(distance, 2))
    if distance < STOP_AT:
        break
    time.sleep(0.02)
bot.stop()
print(f"Stopped {bot.sensors()['range']:.2f} m before the wall")
