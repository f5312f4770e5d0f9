"""O mesmo programa em qualquer robô: anda 1 s para a frente, gira, para e diz o que ele sente.

Só muda o robô por trás da API: uma simulação, um robô de tons DTMF, um Lego NXT, um Pioneer,
um veículo MAVLink ou uma base em barramento CAN. Sensores que o robô não tem são pulados, não
são um erro.
"""

import time

import robot

bot = robot.Robot()
tem = bot.capabilities()["sensors"]

bot.drive(0.2, 0.0)  # para a frente a 0,2 m/s
time.sleep(1.0)
bot.drive(0.0, 1.0)  # gira para a esquerda a 1 rad/s
time.sleep(1.0)
bot.stop()

print("parado num robô do tipo", bot.capabilities()["kind"])
leituras = bot.sensors()
for nome in ("heading", "range"):
    if nome not in tem:
        print(f"{nome}: este robô não tem esse sensor")
    elif leituras[nome] is None:
        print(f"{nome}: sem leitura")
    else:
        print(f"{nome}: {leituras[nome]:.2f} {tem[nome]['unit']}")
