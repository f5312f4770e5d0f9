"""Lê a bússola, diz o rumo e desenha uma bússola na página do robô.

O exemplo 1 do artigo, e a bússola da sua figura 6 desenhada pelo código do usuário.
"""

import math
import time

import robot

bot = robot.Robot()


def bussola_svg(rumo):
    angulo = math.radians(rumo)
    x, y = 50 + 26 * math.sin(angulo), 50 - 26 * math.cos(angulo)
    return (
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100" width="160" height="160">'
        '<circle cx="50" cy="50" r="45" fill="#fff" stroke="#334" stroke-width="3"/>'
        '<text x="50" y="17" text-anchor="middle" font-size="11" font-family="sans-serif">N</text>'
        f'<line x1="50" y1="50" x2="{x:.1f}" y2="{y:.1f}" stroke="#c22" stroke-width="5"'
        ' stroke-linecap="round"/><circle cx="50" cy="50" r="4" fill="#334"/></svg>'
    )


bot.drive(0.0, 0.4)  # gira devagar, para a agulha se mexer
for _ in range(30):
    rumo = bot.sensors()["heading"]
    print(f"Meu rumo é {rumo:.0f} graus")
    bot.show("rumo", round(rumo) % 360)
    bot.show("bússola", bussola_svg(rumo))
    time.sleep(1)
bot.stop()
