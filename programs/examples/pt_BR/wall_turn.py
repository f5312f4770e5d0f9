"""Anda até a parede, vira para longe dela e diz o rumo."""

import time

import robot

bot = robot.Robot()

bot.drive(0.3, 0.0)
while bot.sensors()["range"] >= 0.5:  # metros
    time.sleep(0.02)
bot.stop()

bot.drive(0.0, 1.0)  # gira a 1 rad/s
time.sleep(1.5)
bot.stop()

rumo = round(bot.sensors()["heading"], 1)
print(f"rumo: {rumo:.1f}")
bot.show("rumo", rumo)
