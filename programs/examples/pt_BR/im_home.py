"""Cheguei em casa: anda por aí até a câmera ver o código "home" (casa), então diz e para.

O segundo exemplo do artigo: etiquetas com códigos de barras são marcos que um robô reconhece
com a sua câmera. No simulador, códigos QR com os nomes dos cômodos estão nas paredes da arena
(escritos em inglês, como um código: "home", "kitchen", "lab", "garage"). Em cada parede o robô
dá uma volta completa no lugar (pela bússola), lendo os códigos à vista, e depois segue para
onde o acaso mandar.
"""

import random
import time

import robot

CASA = "home"  # o texto do código QR da casa
COMODOS = {"home": "casa", "kitchen": "cozinha", "lab": "laboratório", "garage": "garagem"}
VELOCIDADE = 0.25  # m/s
GIRO = 0.8  # rad/s
bot = robot.Robot()
vistos = set()


def casa_a_vista():
    """Lê os códigos à vista; diz quais são novos; True se um deles é a casa."""
    textos = [codigo["text"] for codigo in bot.scan_barcode()]
    for texto in textos:
        if texto not in vistos:
            vistos.add(texto)
            nome = COMODOS.get(texto, texto)
            print(f"Estou vendo: {nome}", flush=True)
            bot.show("marco", nome)
    return CASA in textos


def olhar_em_volta():
    """Dá uma volta completa no lugar, olhando: True assim que a casa estiver à vista."""
    bot.drive(0.0, GIRO)
    girado, ultimo = 0.0, bot.sensor("heading")
    while girado < 360:
        if casa_a_vista():
            return True
        time.sleep(0.05)
        rumo = bot.sensor("heading")
        girado += abs((rumo - ultimo + 540) % 360 - 180)
        ultimo = rumo
    return False


def passear():
    """Anda por aí até a casa estar à vista."""
    while not casa_a_vista():
        leituras = bot.sensors()
        if leituras["bumper"] or leituras["range"] < 0.6:  # m: tem algo à frente
            if leituras["bumper"]:
                bot.drive(-0.15, 0.0)  # primeiro dá ré
                time.sleep(0.4)
            if olhar_em_volta():
                return
            bot.drive(0.0, random.choice((-GIRO, GIRO)))  # um novo caminho, ao acaso
            time.sleep(random.uniform(0.5, 3.0))
            while bot.sensor("range") < 0.6:  # e um caminho livre
                time.sleep(0.05)
        bot.drive(VELOCIDADE, 0.0)
        time.sleep(0.05)


passear()
bot.stop()
print("Cheguei em casa", flush=True)
bot.say("Cheguei em casa")
