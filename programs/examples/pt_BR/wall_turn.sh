#!/bin/sh
# Anda até a parede, vira para longe dela e diz o rumo.
set -e

abaixo() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a < b) }'; }

robot drive 0.3 0
until abaixo "$(robot sensors range)" 0.5; do  # metros
    sleep 0.02
done
robot stop

robot drive 0 1.0  # gira a 1 rad/s
sleep 1.5
robot stop

rumo=$(awk -v h="$(robot sensors heading)" 'BEGIN { printf "%.1f", h }')
echo "rumo: $rumo"
robot show rumo "$rumo"
