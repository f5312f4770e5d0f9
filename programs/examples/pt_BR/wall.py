"""Anda em frente e para antes da parede, usando o sensor de distância."""

import time

import robot

bot = robot.Robot()
PARAR_A = 0.5  # metros

bot.drive(0.3, 0.0)
while True:
    distancia = bot.sensors()["range"]
    bot.show("distância", round(distancia, 2))
    if distancia < PARAR_A:
        break
    time.sleep(0.02)
bot.stop()
print(f"Parei a {bot.sensors()['range']:.2f} m da parede")
