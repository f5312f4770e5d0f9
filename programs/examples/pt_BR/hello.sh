#!/bin/sh
# A API do robô pelo shell: o comando robot imprime o que ele lê.
echo "Meu rumo é $(robot sensors heading) graus"
robot drive 0.2 0
sleep 2
robot stop
echo "A parede à frente está a $(robot sensors range) m"
