"""Drive a square: straight ahead, then a quarter turn on the compass, four times."""

import time

import robot

bot = robot.Robot()
SPEED = 0.2  # m/s
SIDE = 0.8  # m


def turn_right_90():
    target = (bot.sensors()["heading"] + 90) % 360
    bot.drive(0.0, -0.8)  # negative angular speed turns clockwise
    while True:
        error = (target - bot.sensors()["heading"] + 540) % 360 - 180
        if abs(error) < 2:
            break
        time.sleep(0.01)
    bot.stop()


for side in range(1, 5):
    print(f"side {side}")
    bot.drive(SPEED, 0.0)
    time.sleep(SIDE / SPEED)
    bot.stop()
    turn_right_90()

position = bot.sensors()["position"]
print(f"back near the start: x={position['x']:.2f} m, y={position['y']:.2f} m")
