#!/bin/sh
# Drive to the wall, turn away from it, and tell the heading.
set -e

below() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a < b) }'; }

robot drive 0.3 0
until below "$(robot sensors range)" 0.5; do  # metres
    sleep 0.02
done
robot stop

robot drive 0 1.0  # turn at 1 rad/s
sleep 1.5
robot stop

heading=$(awk -v h="$(robot sensors heading)" 'BEGIN { printf "%.1f", h }')
echo "heading: $heading"
robot show heading "$heading"
