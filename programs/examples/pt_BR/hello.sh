#!/bin/sh
# A API do robô pelo shell: o comando robot imprime o que ele lê.
printf 'Meu rumo é %.0f graus\n' "$(robot sensors heading)"
robot drive 0.2 0
sleep 2
robot stop
printf 'A parede à frente está a %.2f m\n' "$(robot sensors range)"
