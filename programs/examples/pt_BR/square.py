"""Anda em quadrado: em frente, depois um quarto de volta pela bússola, quatro vezes."""

import time

import robot

bot = robot.Robot()
VELOCIDADE = 0.2  # m/s
LADO = 0.8  # m


def virar_90_a_direita():
    alvo = (bot.sensors()["heading"] + 90) % 360
    bot.drive(0.0, -0.8)  # velocidade angular negativa gira no sentido horário
    while True:
        erro = (alvo - bot.sensors()["heading"] + 540) % 360 - 180
        if abs(erro) < 2:
            break
        time.sleep(0.01)
    bot.stop()


for lado in range(1, 5):
    print(f"lado {lado}")
    bot.drive(VELOCIDADE, 0.0)
    time.sleep(LADO / VELOCIDADE)
    bot.stop()
    virar_90_a_direita()

posicao = bot.sensors()["position"]
print(f"de volta perto do início: x={posicao['x']:.2f} m, y={posicao['y']:.2f} m")
