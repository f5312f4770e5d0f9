"""Diga "move" e o robô anda: comandos falados, reconhecidos no computador do robô, offline.

O terceiro exemplo do artigo. O reconhecedor de fala (pocketsphinx) vem com o modelo do
inglês, por isso os comandos são palavras em inglês: diga "move" (anda 20 cm), "left" ou
"right" (um quarto de volta para a esquerda ou a direita) ou "stop" (o robô diz a que distância
está a parede à frente, e o programa termina). Passe arquivos WAV da pasta do programa como
argumentos para tocá-los para o robô, um de cada vez, em vez do microfone.

No robô simulado, que não tem microfone, digite o comando na caixa "Diga ao robô" da página do
robô ou ao lado do editor e tecle Enter: listen() ouve o que é digitado ali (num robô com
microfone também, o que vier primeiro).
"""

import sys
import time

import robot

COMANDOS = ["move", "left", "right", "stop"]
bot = robot.Robot()


def comandos():
    """O que foi ouvido, um comando de cada vez ("" quando não foi nenhum deles)."""
    gravacoes = sys.argv[1:]
    if gravacoes:
        for wav in gravacoes:
            yield bot.listen(wav=wav, words=COMANDOS)["text"]
        return
    print("Diga move, left, right ou stop", flush=True)
    bot.say("Say move, left, right or stop")  # em inglês: as palavras que ele reconhece
    while True:
        yield bot.listen(3, words=COMANDOS)["text"]


def mover(linear, angular, segundos):
    bot.drive(linear, angular)
    time.sleep(segundos)
    bot.stop()


for comando in comandos():
    if not comando:
        continue
    print(f"ouvi: {comando}", flush=True)
    bot.show("ouvido", comando)
    if comando == "move":
        mover(0.2, 0.0, 1.0)
    elif comando == "left":
        mover(0.0, 0.8, 1.96)  # cerca de um quarto de volta
    elif comando == "right":
        mover(0.0, -0.8, 1.96)
    else:
        bot.stop()
        distancia = f"{bot.sensor('range'):.1f}".replace(".", ",")
        print(f"A distância é {distancia} metros", flush=True)
        bot.say(f"A distância é {distancia} metros")
        break
